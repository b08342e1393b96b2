"""``make demo``: the ``walk`` scene with the controller in the loop, recorded, summarised and plotted.

Owns the demo's orchestration only. It starts ``sim_node`` with ``msg_configs/walk.yaml`` (or the
``--scene``'s file; lockstep, recording on) and the ``walk_controller`` node in a second process; a scene
without a ``walk_controller`` section (the passive ``compass_gait``) runs ``sim_node`` alone, fast, u = 0.
Both run on the exported ``ROS_DOMAIN_ID`` (else a free ROS domain), limited to this machine; the sim node
ends at ``--duration`` s of simulated time, closing its bag; then ``biped-sim inspect BAG`` prints the
run's summary and writes the PNG. Without rclpy (or if the nodes cannot run here) it falls back to the
same run headless: ``biped-sim simulate --scene walk --record`` (or, without the recorder, the summary only).
"""
from __future__ import annotations

import argparse
import contextlib
import os
import random
import subprocess
import sys
import time
from pathlib import Path

from biped_sim.cli import main as cli_main
from biped_sim.config.command_errors import CommandError, run_command
from biped_sim.config.scenes import load_scene

BIN = Path(sys.executable).parent


#: the largest ROS_DOMAIN_ID ROS 2 accepts (its ports must fit below 65535 with the default DDS layout)
MAX_DOMAIN_ID = 232


@contextlib.contextmanager
def _domain(environ=None):
    """(domain, where it came from): an exported ``ROS_DOMAIN_ID`` as it is (labs assign each seat a
    domain, and a demo on another one is invisible to their tools), else a free domain reserved with
    ``domain_coordinator`` (else a random one in 100-200)."""
    given = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "").strip()
    if given:
        if not given.isdigit() or int(given) > MAX_DOMAIN_ID:
            raise ValueError(f"ROS_DOMAIN_ID={given!r}: expected an integer from 0 to {MAX_DOMAIN_ID}")
        yield int(given), "ROS_DOMAIN_ID"
        return
    try:
        import domain_coordinator
    except ImportError:
        yield random.randint(100, 200), "a random one in 100-200: ROS_DOMAIN_ID unset"
        return
    reserved = domain_coordinator.domain_id()
    dom = reserved.__enter__()
    try:
        yield int(dom), "a free one: ROS_DOMAIN_ID unset"
    finally:
        # released without the exception: domain_id's generator takes an OSError thrown into it for a
        # taken port and tries the next domain, which hid every OSError of the run ("generator didn't
        # stop after throw()")
        reserved.__exit__(None, None, None)


def _start(argv, env, log):
    return subprocess.Popen(argv, env=env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)


def _stop(proc, timeout=10.0):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def run_nodes(scene, duration, bag_dir: Path, timeout: float):
    """The two nodes over DDS; returns the new bag's path, or raises RuntimeError."""
    import rclpy  # noqa: F401  (fail early, into the headless fallback, if ROS is missing)
    bag_dir.mkdir(parents=True, exist_ok=True)
    before = {p for p in bag_dir.iterdir() if p.is_dir()}
    logs = bag_dir / "demo-logs"
    logs.mkdir(exist_ok=True)
    with _domain() as (dom, source):
        env = dict(os.environ, ROS_DOMAIN_ID=str(dom), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0")
        params = ["--ros-args", "--params-file", str(scene.path)]
        # a scene without a walk_controller section (compass_gait: passive) has no controller to wait for:
        # the node runs alone, fast, with u = 0 (no command timeout: no command comes)
        passive = scene.controller_params is None
        mode = ["-p", "time_mode:=fast", "-p", "command_timeout:=0.0"] if passive else ["-p", "time_mode:=lockstep"]
        sim_argv = [str(BIN / "sim_node"), *params, "-p", f"duration:={float(duration)!r}", *mode,
                    "-p", "record:=true", "-p", f"bag_dir:={bag_dir}"]
        ctl_argv = None if passive else [str(BIN / "walk_controller"), *params]
        print(f"ROS domain {dom} ({source}): sim_node ({scene.name} scene, "
              + (f"fast, {duration:g} s, u = 0: the scene has no controller)" if passive
                 else f"lockstep, {duration:g} s) + walk_controller") + f"; logs in {logs}/", flush=True)
        with open(logs / "sim_node.log", "wb") as sim_log, open(logs / "walk_controller.log", "wb") as ctl_log:
            t0 = time.monotonic()
            sim = _start(sim_argv, env, sim_log)
            ctl = None if ctl_argv is None else _start(ctl_argv, env, ctl_log)
            try:
                while sim.poll() is None:
                    if time.monotonic() - t0 > timeout:
                        raise RuntimeError(f"the run did not end within {timeout:g} s of wall time")
                    if ctl is not None and ctl.poll() is not None:
                        raise RuntimeError(f"walk_controller exited with code {ctl.returncode}")
                    time.sleep(0.1)
                wall = time.monotonic() - t0
            finally:
                code_sim = _stop(sim)
                if ctl is not None:
                    _stop(ctl)
        if code_sim == 2:       # sim_node refused to start (its bag folder, say): the fallback would too
            raise CommandError(f"sim_node refused to start: {_last_error(logs / 'sim_node.log')} (log: "
                               f"{logs / 'sim_node.log'})")
        if code_sim != 0:
            raise RuntimeError(f"sim_node exited with code {code_sim}: {_last_error(logs / 'sim_node.log')} "
                               f"(log: {logs / 'sim_node.log'})")
        print(f"the nodes ran {duration:g} s of simulated time in {wall:.1f} s of wall time "
              "(processes started and discovered each other included)")
        ctl_lines = (logs / "walk_controller.log").read_text().strip().splitlines()
        if ctl_lines:
            print(ctl_lines[-1])
    new = sorted({p for p in bag_dir.iterdir() if p.is_dir()} - before - {logs})
    if not new:
        raise RuntimeError(f"sim_node did not write a bag: {_last_error(logs / 'sim_node.log')} (log: "
                           f"{logs / 'sim_node.log'})")
    return new[-1]


def _last_error(log: Path) -> str:
    """The last error line of a node's log (the node's own one-line refusal), or its last line."""
    lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    errors = [ln for ln in lines if "error" in ln.lower()]
    return (errors or lines or ["(empty log)"])[-1]


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m biped_sim.cli.demo", description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="walk")
    ap.add_argument("--duration", type=float, default=5.0, help="simulated seconds")
    ap.add_argument("--bag-dir", default="bags")
    ap.add_argument("--timeout", type=float, default=180.0, help="wall seconds before giving up on the nodes")
    ap.add_argument("--headless", action="store_true", help="skip ROS: the headless run")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    print(f"biped_sim demo: scene {scene.name} ({scene.path})")
    bag = None
    if not args.headless:
        try:
            bag = run_nodes(scene, args.duration, Path(args.bag_dir), args.timeout)
        except (ImportError, RuntimeError) as exc:
            # an OSError (a bag folder that cannot be written) is not caught: the headless run would meet
            # it too; it ends the demo with its one line (command_errors)
            print(f"the ROS run did not work here ({exc}); falling back to the headless run", flush=True)
    if bag is None:
        try:
            import biped_sim.recording.recorder  # noqa: F401
        except ImportError:
            return cli_main(["simulate", "--scene", str(scene.path), "--duration", str(args.duration)])
        before = set(Path(args.bag_dir).glob("*/")) if Path(args.bag_dir).is_dir() else set()
        code = cli_main(["simulate", "--scene", str(scene.path), "--duration", str(args.duration),
                         "--record", args.bag_dir])
        new = sorted(set(Path(args.bag_dir).glob("*/")) - before)
        if code != 0 or not new:
            return code or 1
        bag = new[-1]
    print(f"\nbag {bag}\n")
    return cli_main(["inspect", str(bag)])


if __name__ == "__main__":
    sys.exit(run_command("make demo", main))
