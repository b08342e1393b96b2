"""Benchmark: what recording costs a run (``python -m benchmarks.bench_record``).

Owns the recording benchmark of issue 4. The walking scene runs headless the way the node runs
it (one ``advance`` per control period, every state message built with the node's message
functions, as ``fast`` mode publishes them) three ways, interleaved and repeated:

* ``engine``: ``hybrid.simulate(..., control_period=...)``, no messages at all;
* ``publish``: the node's loop with its messages built but not recorded (the node without a bag);
* ``record``: the same loop with every message recorded to a bag (serialised, handed to the
  writer process).

It prints the real-time factor (simulated s per wall s) of each (best of the repeats), the cost
ratio of recording relative to ``publish`` (the issue's target: at most 10 %) and relative to the
bare engine, the time ``close()`` takes after the run, and the bag's size.
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
import time
from pathlib import Path


def _runs(duration, period):
    from biped_sim.config import parameters as P
    from biped_sim.control.walking import WalkingController
    from biped_sim.engine.model import BipedModel
    ctrl = WalkingController(BipedModel())
    q0, dq0 = ctrl.initial_state()
    params = P.validate(dict(scene="bench", time_mode="fast", duration=duration, control_period=period,
                             publish_rate=1.0 / period, initial_q=[float(v) for v in q0],
                             initial_dq=[float(v) for v in dq0]))
    return params, ctrl


def bench(duration=2.0, period=0.001, repeats=5, folder=None):
    """The headless figures (see the module docstring); lists of real-time factors per configuration."""
    from biped_sim.engine.simulate import simulate
    from biped_sim.config.parameters import engine_arguments
    from biped_sim.recording.record_run import run_recorded, topics_for
    from biped_sim.recording.recorder import BagRecorder
    params, ctrl = _runs(duration, period)
    tmp = Path(folder or tempfile.mkdtemp(prefix="bench-record-"))
    res = {k: [] for k in ("engine", "publish", "record", "engine_cpu", "publish_cpu", "record_cpu", "close",
                           "writer_cpu")}
    kw = engine_arguments(params)
    model = kw.pop("model")
    kw = {k: v for k, v in kw.items() if k not in ("q0", "dq0")}
    run_recorded(params, ctrl, None, build_messages=True)     # warm up (imports, type support)

    def timed(key, fn):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        t1, c1 = time.perf_counter(), time.process_time()
        res[key].append(duration / (t1 - t0))
        res[key + "_cpu"].append(duration / (c1 - c0))
    for i in range(repeats):
        timed("engine", lambda: simulate(model, params["initial_q"], params["initial_dq"], duration, controller=ctrl,
                                         control_period=period, **kw))
        timed("publish", lambda: run_recorded(params, ctrl, None, build_messages=True))
        path = tmp / f"bag{i}"
        rec = BagRecorder(path, parameters=params)
        for name, typ in topics_for(params).items():   # as the node does before its run
            rec.add_topic(name, typ)
        _wait_idle(rec._proc.pid)        # let the writer process finish starting (imports: ~1 s of CPU here)
        w0 = _proc_cpu(rec._proc.pid)
        timed("record", lambda: run_recorded(params, ctrl, rec, build_messages=True))
        w1 = _proc_cpu(rec._proc.pid)
        t1 = time.perf_counter()
        rec.close()
        res["close"].append(time.perf_counter() - t1)
        res["writer_cpu"].append(w1 - w0)
        res["size"] = sum(f.stat().st_size for f in path.iterdir())
        res["messages"] = sum(rec.message_counts.values())
    res["write_us"] = _write_cost(params, tmp / "isolated")
    if folder is None:
        shutil.rmtree(tmp, ignore_errors=True)
    return res


def _wait_idle(pid, timeout=15.0):
    """Wait until a process has used no CPU for 0.2 s (its start-up is over), at most ``timeout`` s."""
    end = time.monotonic() + timeout
    last = _proc_cpu(pid)
    while time.monotonic() < end:
        time.sleep(0.2)
        now = _proc_cpu(pid)
        if now == last:
            return
        last = now


def _proc_cpu(pid):
    """CPU seconds (user + system) a process has used so far (Linux /proc), 0 if unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def _write_cost(params, path, n=4000):
    """CPU us per control period of what recording adds in the simulating process, measured alone:
    the hip_torque command's CDR and ``write``, and the state's ``write_state`` (pack + hand over,
    as the node does), best of 3."""
    from biped_sim.recording import messages as M
    from biped_sim.recording.cdr import float64_multi_array_data
    from biped_sim.recording.record_run import topics_for
    from biped_sim.recording.recorder import BagRecorder
    q, dq = params["initial_q"], params["initial_dq"]
    rec = BagRecorder(path, parameters=params)
    for name, typ in topics_for(params).items():
        rec.add_topic(name, typ)
    best = float("inf")
    for _ in range(3):
        c0 = time.thread_time()
        for k in range(n):
            rec.write("/hip_torque", float64_multi_array_data([1.0, -2.0]), k)
            rec.write_state(k, ("/joint_states", "/ground_reaction", "/clock"), "foot_1", M.JOINT_NAMES, q, dq,
                            [0.0, 0.0, 1.0, 2.0, 0.0], [1.0, 200.0])
        best = min(best, (time.thread_time() - c0) / n * 1e6)
    rec.close()
    return best


def node_bench(duration=3.0, repeats=3):
    """``sim_node`` in ``fast`` mode (1 kHz publish rate, u = 0 from the balanced default state), with and
    without recording: the real-time factor from the node's own log times (start line to 'reached')."""
    import re
    import subprocess
    import sys
    try:
        import domain_coordinator
    except ImportError:
        return None
    exe = Path(sys.executable).parent / "sim_node"
    if not exe.exists():
        return None
    stamp = re.compile(r"\[(\d+\.\d+)\]")
    out = {False: [], True: []}
    tmp = Path(tempfile.mkdtemp(prefix="bench-node-"))
    with domain_coordinator.domain_id() as dom:
        env = dict(os.environ, ROS_DOMAIN_ID=str(dom), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   RCUTILS_COLORIZED_OUTPUT="0")
        for _ in range(repeats):
            for record in (False, True):
                args = [str(exe), "--ros-args", "-p", "time_mode:=fast", "-p", f"duration:={duration!r}",
                        "-p", "control_period:=0.001", "-p", "publish_rate:=1000.0", "-p", "command_timeout:=0.0",
                        "-p", f"record:={'true' if record else 'false'}", "-p", f"bag_dir:={tmp}",
                        "-p", "scene:=bench"]
                p = subprocess.run(args, env=env, capture_output=True, text=True, timeout=300)
                lines = (p.stdout + p.stderr).splitlines()
                t0 = next((float(stamp.search(x).group(1)) for x in lines if "time_mode=fast" in x and stamp.search(x)), None)
                t1 = next((float(stamp.search(x).group(1)) for x in lines if "reached" in x and stamp.search(x)), None)
                if t0 is None or t1 is None or p.returncode != 0:
                    shutil.rmtree(tmp, ignore_errors=True)
                    raise RuntimeError(f"sim_node run failed (code {p.returncode}):\n" + "\n".join(lines[-20:]))
                out[record].append(duration / (t1 - t0))
    shutil.rmtree(tmp, ignore_errors=True)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_record", description=__doc__.split("\n\n")[1],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--duration", type=float, default=2.0, help="simulated seconds per run")
    p.add_argument("--period", type=float, default=0.001, help="control period = publish period (s)")
    p.add_argument("--repeats", type=int, default=9, help="interleaved repeats")
    p.add_argument("--node", action="store_true",
                   help="also time sim_node in fast mode with and without recording (3 runs each; slow, and "
                        "its figures are dominated by rclpy's executor wait on a busy machine)")
    p.add_argument("--node-duration", type=float, default=3.0, help="simulated seconds per sim_node run")
    a = p.parse_args(argv)
    r = bench(a.duration, a.period, a.repeats)
    best = {k: max(v) for k, v in r.items() if isinstance(v, list) and v and k not in ("close", "writer_cpu")}
    med = {k: sorted(v)[len(v) // 2] for k, v in r.items() if isinstance(v, list) and v}
    print(f"walking scene, {a.duration:g} s simulated per run, control period {a.period * 1e3:g} ms; recorded: "
          f"joint_states, ground_reaction, clock, hip_torque every period ({r['messages']} messages); best of "
          f"{a.repeats} interleaved runs; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    print("  real-time factor (simulated s / wall s, and / CPU s of the simulating process)")
    for k, what in (("engine", "bare engine (simulate, no messages)"),
                    ("publish", "node loop, messages built as the node publishes them, no bag"),
                    ("record", "node loop, every message recorded")):
        print(f"    {what:62s} wall {best[k]:6.3f} (median {med[k]:6.3f})   CPU {best[k + '_cpu']:6.3f} "
              f"(median {med[k + '_cpu']:6.3f})")
    # each repeat runs publish then record back to back: their ratio sees the same machine, so the
    # median of the paired ratios is the steadiest figure on a shared machine
    paired = sorted(1.0 - r["record_cpu"][i] / r["publish_cpu"][i] for i in range(len(r["record_cpu"])))
    print(f"  recording cost (paired): {paired[len(paired) // 2] * 100:5.1f} % of the CPU real-time factor, median "
          f"of {len(paired)} back-to-back pairs (range {paired[0] * 100:.1f} to {paired[-1] * 100:.1f} %; target <= 10 %: "
          f"{'met' if paired[len(paired) // 2] <= 0.10 else 'not met'})")
    for label, d in (("best", best), ("median", med)):
        cost = 1.0 - d["record"] / d["publish"]
        cost_cpu = 1.0 - d["record_cpu"] / d["publish_cpu"]
        print(f"  recording cost ({label:6s}): {cost * 100:5.1f} % of the wall real-time factor, {cost_cpu * 100:5.1f} % "
              f"of the CPU one (target <= 10 %: {'met' if cost <= 0.10 else 'not met'} / "
              f"{'met' if cost_cpu <= 0.10 else 'not met'})")
    per_period = a.period / best["publish_cpu"] * 1e6
    print(f"  recording work in the simulating process, measured alone: {r['write_us']:.1f} us per control period "
          f"= {r['write_us'] / per_period * 100:.1f} % of the {per_period:.0f} us CPU a period of the node loop takes")
    print(f"  writer process: {min(r['writer_cpu']) / (a.duration / best['record']) * 100:.0f} % of a CPU during the "
          f"recorded run (nice 10; another core when one is free); close() {min(r['close']) * 1e3:.0f} ms after the run")
    if a.node:
        nb = node_bench(a.node_duration, a.repeats if a.repeats < 3 else 3)
        if nb is None:
            print("  sim_node: not available (no rclpy / domain_coordinator): node benchmark skipped")
        else:
            off, on = max(nb[False]), max(nb[True])
            print(f"  sim_node, time_mode fast, {a.node_duration:g} s at 1 kHz publish rate (u = 0, balanced start), "
                  f"{len(nb[False])} runs each: real-time factor without recording {sorted(round(v, 3) for v in nb[False])}, "
                  f"with {sorted(round(v, 3) for v in nb[True])} -> cost of the best {(1 - on / off) * 100:.1f} %")
    print(f"  bag: {r['size'] / 1e6:.2f} MB for {a.duration:g} s ({r['size'] / r['messages']:.0f} B per message, "
          f"zstd chunks)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
