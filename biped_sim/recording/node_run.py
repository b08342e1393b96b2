"""One run as the node runs it, without ROS: the command policy, the control period, where each event
goes, the state as messages, and a restart.

``sim_node`` (commands over DDS), ``simulate --record`` (:mod:`~biped_sim.recording.record_run`: a
controller in this process) and ``resim`` (a bag's commands through a fresh engine) each drive a
:class:`NodeRun`; what a command does, how a period advances and which topic an event goes to are
written here once, so a recorded run, its re-simulation and the node's run cannot drift apart.
"""
from __future__ import annotations

import math

from biped_sim.config.joints import joint_layout
from biped_sim.config.parameters import engine_arguments
from biped_sim.recording.cdr import StateSerializer
from biped_sim.recording.messages import IMPACT_KINDS, foot_frame, to_ns

#: the state messages of a period, in the order ``StateSerializer.period`` gives them
STATE_OUTPUTS = ("joint_states", "ground_reaction", "clock")


def stale_command(answers_ns: int | None, newest_ns: int, before_reset_ns: int | None = None) -> str | None:
    """Why a lockstep command tagged as the answer to the state ``answers_ns`` is not taken when the
    newest state is ``newest_ns``, or None (untagged, or the answer to the newest state).
    ``before_reset_ns``: the latest state the runs before a ``~/reset`` reached (None: no reset), so
    that a late answer to one of them is called what it is, not blamed on another simulation."""
    if answers_ns is None or answers_ns == newest_ns:
        return None
    if before_reset_ns is not None and newest_ns < answers_ns <= before_reset_ns:
        return (f"it answers the state at t={answers_ns * 1e-9:.6f} s of the run before the ~/reset (which "
                f"reached t={before_reset_ns * 1e-9:.6f} s): a late answer to the old run; the run restarted "
                "at t = 0 and takes the answer to its newest state")
    where = (f"the state at t={answers_ns * 1e-9:.6f} s, an older one: a restarted or a second controller "
             "answers states the run has gone past" if answers_ns < newest_ns else
             f"the state at t={answers_ns * 1e-9:.6f} s, which this node has not published: another "
             "simulation on this ROS domain?")
    return f"it answers {where}"


def event_output(event) -> str:
    """The output an engine event is published on: ``impact`` for a touchdown, ``diagnostics`` for any
    other (liftoff, scuff, push, error...)."""
    return "impact" if event.kind in IMPACT_KINDS else "diagnostics"


class NodeRun:
    """The engine of one run with the node's rules around it.

    ``params``: checked parameters (:func:`biped_sim.config.parameters.validate`). ``labels``: what each
    state message is named by in :meth:`state_messages` (default the output names; the node uses its
    topic names). ``u`` is the torque held: the last command taken, zero before the first.
    """

    def __init__(self, params, labels=None):
        self.params = params
        self.period = params["control_period"]
        self.duration = params["duration"]
        self.limit = params["torque_limit"]
        self.clip = params["torque_limit_action"] == "clip"
        outputs = set(params["outputs"])
        self.state_outputs = tuple(name in outputs for name in STATE_OUTPUTS)
        # joint_states' names and effort, a command's length: the robot's (config.joints)
        self.layout = joint_layout(params.get("robot", "three_link"))
        self.n_actuated = len(self.layout.actuated)
        self._largest, self._floats = self.layout.command_functions()
        self.serializer = self._serializer(labels)
        self.counts = dict(rejected=0, clipped=0)
        self.u = self.zero_torque()
        self.restart()

    def restart(self):
        """A fresh engine at the scene's initial state (t = 0). The held torque stays: the caller decides
        (a lockstep controller's answer to the untouched t = 0 state stands over a reset)."""
        from biped_sim.engine.hybrid import HybridSimulator
        self.sim = HybridSimulator(**engine_arguments(self.params), keep_samples=False)
        self.finished = False           # the duration is reached
        self.stopped = False            # the engine stopped (an error, a fall, a refused start)
        return self.sim

    def label_states(self, labels):
        """Name the state messages of :meth:`state_messages` by ``labels`` ({output name: label}, e.g.
        the node's topic names) instead of the output names."""
        self.serializer = self._serializer(labels)

    def _serializer(self, labels):
        return StateSerializer(self.layout.coordinates, labels=labels, effort=self.layout.effort_function())

    def zero_torque(self) -> list:
        """u = 0: one zero per actuated joint."""
        return [0.0] * len(self.layout.actuated)

    @property
    def running(self) -> bool:
        return not (self.finished or self.stopped)

    # -- commands -------------------------------------------------------------------------------
    def check_command(self, data):
        """(torques, why) of a command's values: (the floats, None) taken; (clipped, why) beyond
        ``torque_limit`` with ``torque_limit_action`` clip; (None, why) refused: not one finite value per
        actuated joint, or beyond the limit with reject (the held torque stays). Counts the refused and the
        clipped."""
        if len(data) != self.n_actuated:
            why = f"{len(data)} values instead of {self.layout.command_line()}"
        elif not all(math.isfinite(v) for v in data):
            why = f"not finite: {list(data)}"
        elif self._largest(data) <= self.limit:
            return self._floats(data), None
        else:
            why = f"{list(data)} beyond torque_limit {self.limit:g} N m"
            if self.clip:
                self.counts["clipped"] += 1
                return [max(-self.limit, min(self.limit, float(v))) for v in data], why
        self.counts["rejected"] += 1
        return None, why

    def take_command(self, data):
        """:meth:`check_command`, and the torques it gives are held from now on; returns (torques or None, why)."""
        u, why = self.check_command(data)
        if u is not None:
            self.u = u
        return u, why

    # -- the period ----------------------------------------------------------------------------------
    def advance(self, pushes=()):
        """One control period with the held torques, after ``pushes`` (impulses received since the last
        period, applied at its start). Returns (events, ended): the events of the pushes and the period
        in order, and "stopped" / "finished" when the run ended in this period, else None."""
        sim = self.sim
        events = []
        for impulse in pushes:
            events.extend(sim.push(impulse))
        events.extend(sim.advance_period(self.period, u=self.u, t_final=self.duration))
        ended = None
        if sim.status != "running":
            if not self.stopped:
                self.stopped, ended = True, "stopped"
        elif self.duration > 0 and sim.t >= self.duration and not self.finished:
            self.finished, ended = True, "finished"
        return events, ended

    def advance_to(self, t_ns: int):
        """Control periods until the engine's time reaches ``t_ns`` (a recorded message's stamp) or it
        stops; returns their events."""
        events = []
        while to_ns(self.sim.t) < t_ns and self.sim.status == "running":
            events.extend(self.advance()[0])
        return events

    # -- the state as messages ------------------------------------------------------------------------
    def state_messages(self) -> list:
        """[(label, CDR bytes)] of the state messages of the period just ended, those in ``outputs``:
        joint_states (effort B u: the torque held over the period that ends here), ground_reaction (in
        stance) and clock, stamped with the engine's time."""
        sim = self.sim
        return self.serializer.period(to_ns(sim.t), foot_frame(sim.stance_leg), *sim.state_lists(), self.u,
                                      sim.ground_force if sim.stance_leg else None, *self.state_outputs)
