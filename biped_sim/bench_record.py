"""Benchmark: what recording costs a run (``python -m biped_sim.bench_record``).

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
    from . import parameters as P
    from .control import WalkingController
    from .model import BipedModel
    ctrl = WalkingController(BipedModel())
    q0, dq0 = ctrl.initial_state()
    params = P.validate(dict(scene="bench", time_mode="fast", duration=duration, control_period=period,
                             publish_rate=1.0 / period, initial_q=[float(v) for v in q0],
                             initial_dq=[float(v) for v in dq0]))
    return params, ctrl


def bench(duration=2.0, period=0.001, repeats=5, folder=None):
    from .hybrid import simulate
    from .parameters import engine_arguments
    from .record_run import run_recorded, topics_for
    from .recorder import BagRecorder
    params, ctrl = _runs(duration, period)
    tmp = Path(folder or tempfile.mkdtemp(prefix="bench-record-"))
    res = {k: [] for k in ("engine", "publish", "record", "engine_cpu", "publish_cpu", "record_cpu", "close",
                           "writer_cpu")}
    kw = engine_arguments(params)
    model = kw.pop("model")
    kw = {k: v for k, v in kw.items() if k not in ("q0", "dq0")}
    run_recorded(params, ctrl, None)     # warm up (imports, type support)

    def timed(key, fn):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        t1, c1 = time.perf_counter(), time.process_time()
        res[key].append(duration / (t1 - t0))
        res[key + "_cpu"].append(duration / (c1 - c0))
    for i in range(repeats):
        timed("engine", lambda: simulate(model, params["initial_q"], params["initial_dq"], duration, controller=ctrl,
                                         control_period=period, **kw))
        timed("publish", lambda: run_recorded(params, ctrl, None))
        path = tmp / f"bag{i}"
        rec = BagRecorder(path, parameters=params)
        for name, typ in topics_for(params).items():   # as the node does before its run
            rec.add_topic(name, typ)
        time.sleep(0.5)                  # let the writer process start (it starts in parallel with a run)
        ch0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        timed("record", lambda: run_recorded(params, ctrl, rec))
        t1 = time.perf_counter()
        rec.close()
        res["close"].append(time.perf_counter() - t1)
        ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        res["writer_cpu"].append(ch1.ru_utime + ch1.ru_stime - ch0.ru_utime - ch0.ru_stime)
        res["size"] = sum(f.stat().st_size for f in path.iterdir())
        res["messages"] = sum(rec.message_counts.values())
    if folder is None:
        shutil.rmtree(tmp, ignore_errors=True)
    return res


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m biped_sim.bench_record", description=__doc__.split("\n\n")[1],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--duration", type=float, default=2.0, help="simulated seconds per run")
    p.add_argument("--period", type=float, default=0.001, help="control period = publish period (s)")
    p.add_argument("--repeats", type=int, default=5, help="interleaved repeats (best of)")
    a = p.parse_args(argv)
    r = bench(a.duration, a.period, a.repeats)
    best = {k: max(v) for k, v in r.items() if isinstance(v, list) and v and k not in ("close", "writer_cpu")}
    print(f"walking scene, {a.duration:g} s simulated per run, control period {a.period * 1e3:g} ms; recorded: "
          f"joint_states, ground_reaction, clock, hip_torque every period ({r['messages']} messages); best of "
          f"{a.repeats} interleaved runs; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    print("  real-time factor (simulated s / wall s, and / CPU s of the simulating process)")
    for k, what in (("engine", "bare engine (simulate, no messages)"),
                    ("publish", "node loop, messages built as the node publishes them, no bag"),
                    ("record", "node loop, every message recorded")):
        print(f"    {what:62s} wall {best[k]:6.3f}   CPU {best[k + '_cpu']:6.3f}")
    cost = 1.0 - best["record"] / best["publish"]
    cost_cpu = 1.0 - best["record_cpu"] / best["publish_cpu"]
    print(f"  recording cost: {cost * 100:.1f} % of the wall real-time factor, {cost_cpu * 100:.1f} % of the CPU one "
          f"(target <= 10 %) -> {'OK' if min(cost, cost_cpu) <= 0.10 else 'ABOVE TARGET'}")
    print(f"  writer process: {min(r['writer_cpu']) / a.duration * 100:.0f} % of a CPU while recording (nice 10, "
          f"another core when one is free); close() {min(r['close']) * 1e3:.0f} ms after the run")
    print(f"  bag: {r['size'] / 1e6:.2f} MB for {a.duration:g} s ({r['size'] / r['messages']:.0f} B per message, "
          f"zstd chunks)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
