"""Shared helpers for tests over real DDS: start a node in a subprocess, talk to it from the test.

Owns process and graph plumbing only (no assertions about the simulator):

* :func:`ros_domain` -- a free ``ROS_DOMAIN_ID`` from ``domain_coordinator`` (context manager);
  every process started here gets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``.
* :func:`start_node` -- ``sim_node`` (or any console script of the venv) with ``-p name:=value``
  parameters, output to a log file; :class:`NodeProcess` stops it with a signal and returns the code.
* :class:`Client` -- an rclpy node in the test process, in its own context on that domain: publishers,
  subscriptions that collect messages, and polling of the graph (never fixed sleeps).
* :func:`bag_messages`, :func:`complete_messages` -- a bag read back by the independent readers
  (rosbags; mcap's stream reader for a file still being written).

Typical use::

    with ros_domain() as dom, start_node({"time_mode": "lockstep"}, dom) as proc, Client(dom) as c:
        js = c.collect("/joint_states", JointState)
        c.wait_for_publisher("/joint_states")
        c.spin_until(lambda: js, timeout=10)
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

BIN = Path(sys.executable).parent
DISCOVERY_TIMEOUT = 20.0


@contextlib.contextmanager
def ros_domain():
    """A free ROS domain id, released at exit."""
    import domain_coordinator
    with domain_coordinator.domain_id() as dom:
        yield int(dom)


def param_text(value) -> str:
    """A parameter value as ``--ros-args -p`` reads it (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(param_text(v) for v in value) + "]"
    return str(value)


def ros_env(domain_id: int) -> dict:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1",
               RCUTILS_COLORIZED_OUTPUT="0")
    return env


class NodeProcess:
    """A started console script; use as a context manager (SIGTERM, then SIGKILL, at exit)."""

    def __init__(self, argv, domain_id, log_path=None):
        self.argv = list(argv)
        if log_path is None:
            fd, log_path = tempfile.mkstemp(prefix="node-", suffix=".log")
            os.close(fd)
        self.log_path = Path(log_path)
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(self.argv, env=ros_env(domain_id), stdout=self._log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def wait(self, timeout=30.0) -> int:
        """The exit code; AssertionError with the node's log if it does not exit within ``timeout`` s."""
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(
                f"{self.argv[0]} did not exit within {timeout} s\n--- log ---\n{self.output()}") from None

    def stop(self, sig=signal.SIGTERM, timeout=15.0) -> int:
        """Send ``sig`` (if still running) and return the exit code; SIGKILL after ``timeout``."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close() if not self._log.closed else None
        return self.proc.returncode


def start_node(params: dict | None = None, domain_id: int = 0, executable: str = "sim_node",
               extra_args=(), log_path=None) -> NodeProcess:
    """Start ``executable`` (a console script of this venv) with ROS parameters ``params``."""
    argv = [str(BIN / executable), *extra_args]
    if params:
        argv.append("--ros-args")
        for name, value in params.items():
            argv += ["-p", f"{name}:={param_text(value)}"]
    return NodeProcess(argv, domain_id, log_path)


class Client:
    """An rclpy node in this process on ``domain_id`` (own context); a context manager."""

    def __init__(self, domain_id: int, name: str = "test_client"):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        if self.context.ok():
            self.executor.shutdown()
            self.node.destroy_node()
            self.context.shutdown()

    @staticmethod
    def qos(depth=1000, transient_local=True):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE)

    def collect(self, topic, msg_type, transient_local=True, callback=None) -> list:
        """Subscribe; every message is appended to the returned list (and passed to ``callback``)."""
        box = []

        def on_msg(msg):
            box.append(msg)
            if callback is not None:
                callback(msg)
        self.node.create_subscription(msg_type, topic, on_msg, self.qos(transient_local=transient_local))
        return box

    def publisher(self, topic, msg_type, depth=1000):
        return self.node.create_publisher(msg_type, topic, self.qos(depth, transient_local=False))

    def spin_once(self, timeout=0.05):
        self.executor.spin_once(timeout_sec=timeout)

    def spin_until(self, predicate, timeout=DISCOVERY_TIMEOUT, what="condition", proc: NodeProcess | None = None):
        """Spin until ``predicate()`` is true; AssertionError after ``timeout`` s (with the node's log)."""
        end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > end:
                log = f"\n--- node log ---\n{proc.output()}" if proc is not None else ""
                raise AssertionError(f"timed out after {timeout} s waiting for {what}{log}")
            if proc is not None and not proc.alive and not predicate():
                self.spin_once(0.05)
                if predicate():
                    return
                raise AssertionError(f"the node exited (code {proc.proc.returncode}) while waiting for {what}"
                                     f"\n--- node log ---\n{proc.output()}")
            self.spin_once(0.05)

    # -- graph ------------------------------------------------------------------------------
    def wait_for_publisher(self, topic, timeout=DISCOVERY_TIMEOUT, proc=None):
        self.spin_until(lambda: self.node.count_publishers(topic) > 0, timeout, f"a publisher on {topic}", proc)

    def wait_for_subscriber(self, topic, timeout=DISCOVERY_TIMEOUT, proc=None):
        self.spin_until(lambda: self.node.count_subscribers(topic) > 0, timeout, f"a subscriber on {topic}", proc)

    def wait_matched(self, publisher, timeout=DISCOVERY_TIMEOUT, proc=None):
        """Until ``publisher`` (ours) is matched by a subscription (so that what it sends arrives)."""
        self.spin_until(lambda: publisher.get_subscription_count() > 0, timeout,
                        f"a match for our publisher on {publisher.topic_name}", proc)

    def wait_subscribed(self, topic, timeout=DISCOVERY_TIMEOUT, proc=None):
        """Until our subscription on ``topic`` is matched by a publisher (so that nothing it sends from
        now on is missed, even by a run that ends before discovery would otherwise complete)."""
        sub = next(s for s in self.node.subscriptions if s.topic_name == topic)
        self.spin_until(lambda: sub.get_publisher_count() > 0, timeout, f"a publisher on {topic}", proc)

    def wait_for_node(self, name, namespace="/", timeout=DISCOVERY_TIMEOUT, proc=None):
        self.spin_until(lambda: (name, namespace) in self.node.get_node_names_and_namespaces(), timeout,
                        f"node {namespace}{name}", proc)

    def node_topics(self, name, namespace="/"):
        """({topic: [types]} published, {topic: [types]} subscribed) of a node (empty if not discovered)."""
        try:
            pubs = dict(self.node.get_publisher_names_and_types_by_node(name, namespace))
            subs = dict(self.node.get_subscriber_names_and_types_by_node(name, namespace))
        except Exception:  # NodeNameNonExistentError: not (yet) in the graph
            return {}, {}
        return pubs, subs

    def wait_for_node_topics(self, name, publishers=(), subscribers=(), namespace="/",
                             timeout=DISCOVERY_TIMEOUT, proc=None):
        """Poll the graph until node ``name`` shows these topics; returns :meth:`node_topics`."""
        def ready():
            pubs, subs = self.node_topics(name, namespace)
            return set(publishers) <= set(pubs) and set(subscribers) <= set(subs)
        self.spin_until(ready, timeout, f"topics {sorted(publishers)} / {sorted(subscribers)} of node {name}", proc)
        return self.node_topics(name, namespace)


def spin_while_running(client, predicate, timeout, what, procs):
    """Spin ``client`` until ``predicate()`` is true: AssertionError after ``timeout`` s, or where one of ``procs``
    has exited with a nonzero code first (one that ended with 0 has done its part), with their logs. (For
    several processes, some of which end on their own: ``Client.spin_until`` watches one, which must stay up.)"""
    end = time.monotonic() + timeout
    while not predicate():
        for p in procs:
            assert p.proc.poll() in (None, 0) or predicate(), f"a process failed waiting for {what}:\n{p.output()}"
        assert time.monotonic() < end, f"timed out waiting for {what}\n" + "\n".join(p.output() for p in procs)
        client.spin_once(0.02)


def bag_messages(bag) -> dict:
    """{topic: [(t_ns, decoded message)]} of a bag, read and decoded by rosbags."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    out = {}
    with Reader(bag) as reader:
        for conn, t_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t_ns, store.deserialize_cdr(raw, conn.msgtype)))
    return out


def complete_messages(paths) -> int:
    """Messages in the complete chunks of MCAP files being written (mcap's stream reader)."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader, breakup_chunk
    n = 0
    for path in paths:
        try:
            with open(path, "rb") as f:
                for rec in StreamReader(f, emit_chunks=True).records:
                    if isinstance(rec, Chunk):
                        n += sum(1 for r in breakup_chunk(rec) if type(r).__name__ == "Message")
        except Exception:  # noqa: BLE001 - the part still being written
            pass
    return n


class Control:
    """Service clients of the node's ~/pause, ~/step, ~/reset (``node``: its fully qualified name)."""

    def __init__(self, client, proc, node="/biped_sim"):
        from std_srvs.srv import SetBool, Trigger
        self.SetBool, self.Trigger = SetBool, Trigger
        self.c, self.proc = client, proc
        self.pause_cli = client.node.create_client(SetBool, f"{node}/pause")
        self.step_cli = client.node.create_client(Trigger, f"{node}/step")
        self.reset_cli = client.node.create_client(Trigger, f"{node}/reset")
        for cli in (self.pause_cli, self.step_cli, self.reset_cli):
            client.spin_until(cli.service_is_ready, what=f"the service {cli.srv_name}", proc=proc)

    def call(self, cli, request):
        future = cli.call_async(request)
        self.c.spin_until(future.done, timeout=30, what=f"the answer of {cli.srv_name}", proc=self.proc)
        return future.result()

    def pause(self, on):
        return self.call(self.pause_cli, self.SetBool.Request(data=on))

    def step(self):
        return self.call(self.step_cli, self.Trigger.Request())

    def reset(self):
        return self.call(self.reset_cli, self.Trigger.Request())
