"""Spinning a node whose work arrives on one subscription: ``sim_node`` in lockstep (``hip_torque``)
and ``walk_controller`` (``joint_states``).

Owns :class:`OneTopicSpin`. rclpy's ``SingleThreadedExecutor.spin_once`` builds a wait set of every
entity of the node -- the six parameter services, the node's own services, its timers, the
subscriptions' QoS event handlers -- and waits on it; that costs more per call than a control period
of the engine (rmw's wait grows with the entities; the figures in docs/node.md and docs/performance.md),
and a lockstep round trip pays it once in each process. :class:`OneTopicSpin` waits on the one
subscription alone and runs its callback, and lets the executor serve everything else --
services, timers, the other subscriptions, and this one too -- at least every ``serve_period`` s of
wall time, without waiting. All callbacks still run one at a time in the calling thread; a service
call or a timer is served at most ``serve_period`` s late.
"""
from __future__ import annotations

import time

from rclpy.executors import ConditionReachedException, ShutdownException, TimeoutException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

#: the longest the executor's other work (services, timers, other topics) waits (wall s)
SERVE_PERIOD = 0.05
#: at most this many of the executor's ready callbacks run at once (then the subscription again)
SERVE_LIMIT = 100


class OneTopicSpin:
    """``spin_once`` for a node whose hot path is ``subscription`` (its callback takes the message only)."""

    def __init__(self, executor, node, subscription, serve_period=SERVE_PERIOD):
        self.executor = executor
        self.subscription = subscription
        self.serve_period = serve_period
        self._wait_set = _rclpy.WaitSet(1, 0, 0, 0, 0, 0, node.context.handle)
        self._next_serve = 0.0          # the first call serves the executor

    def spin_once(self, timeout_sec: float):
        """Run the subscription's callback for the next message if one comes within ``timeout_sec``
        (or before the executor is due); first the executor's ready work, when it is due."""
        now = time.monotonic()
        if now >= self._next_serve:
            self.serve()
            now = time.monotonic()
            self._next_serve = now + self.serve_period
        msg = self._take(max(0.0, min(timeout_sec, self._next_serve - now)))
        if msg is not None:
            self.subscription.callback(msg)

    def _take(self, timeout_sec: float):
        """The next message of the subscription, waiting at most ``timeout_sec``; None if none came."""
        sub, wait_set = self.subscription, self._wait_set
        with sub.handle:
            wait_set.clear_entities()
            wait_set.add_subscription(sub.handle)
            wait_set.wait(int(timeout_sec * 1e9))
            if sub.handle.pointer not in wait_set.get_ready_entities("subscription"):
                return None
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
        return None if taken is None else taken[0]

    def serve(self):
        """Run the callbacks the executor has ready now (as its ``spin_once`` runs one), without waiting."""
        for _ in range(SERVE_LIMIT):
            try:
                handler, _entity, _node = self.executor.wait_for_ready_callbacks(timeout_sec=0)
            except (TimeoutException, ShutdownException, ConditionReachedException):
                return
            handler()
            if handler.exception() is not None:
                raise handler.exception()
