"""``biped-sim animate --scene``: a GIF written and read back with Pillow; bad input in one line."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from PIL import Image

from biped_sim.cli import main as biped_sim
from biped_sim.recording import animation as A, markers as MK


def gif_frames(path):
    with Image.open(path) as im:
        out = []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB")))
        return out, im.info.get("duration")


def colour_pixels(frame, colour, tol=8):
    rgb = np.array([round(255 * c) for c in colour[:3]])
    return int(np.sum(np.all(np.abs(frame.astype(int) - rgb) <= tol, axis=-1)))


def test_animate_a_scene_writes_a_gif_of_the_moving_robot(tmp_path, capsys):
    out = tmp_path / "walk.gif"
    assert biped_sim(["animate", "--scene", "walk", "--duration", "1", "--fps", "10", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "11/11 frames" in err and "100 %" in err           # the progress bar
    frames, ms = gif_frames(out)
    assert len(frames) == 11 and ms == 100                      # 1 s at 10 fps, real time: t = 0, 0.1, ... 1 s
    assert frames[0].shape == (A.HEIGHT, A.WIDTH, 3)
    for f in frames:                                            # the torso, the stance foot, the force arrow
        for colour in (MK.TORSO_COLOUR, MK.STANCE_FOOT_COLOUR, MK.FORCE_COLOUR):
            assert colour_pixels(f, colour) > 10, colour
    for colour in (MK.LEG_COLOURS[1], MK.LEG_COLOURS[2]):      # each leg (one hides the other as they cross)
        assert sum(colour_pixels(f, colour) > 100 for f in frames) >= 9, colour
    assert all(not np.array_equal(a, b) for a, b in zip(frames, frames[1:]))   # the robot moves
    # the walk's first touchdown (t = 0.4716 s) flashes in the frame at 0.5 s
    assert colour_pixels(frames[5], MK.FLASH_COLOUR) > 20 and colour_pixels(frames[3], MK.FLASH_COLOUR) == 0


def test_speed_and_start_choose_the_frames(tmp_path):
    out = tmp_path / "fast.gif"
    assert biped_sim(["animate", "--scene", "walk", "--start", "0.5", "--duration", "1", "--speed", "2", "--fps",
                      "10", "-q", "-o", str(out)]) == 0
    frames, _ = gif_frames(out)
    assert len(frames) == 6                                     # 1 s of simulated time at 2x: 0.5 s at 10 fps


def test_a_gif_keeps_the_speed_with_delays_in_hundredths():
    assert A.gif_fps(20) == 20 and A.gif_fps(30) == pytest.approx(100 / 3) and A.gif_fps(200) == 50


def test_frame_times_follow_speed_and_fps():
    track = A.Track(np.linspace(0, 3, 3001), np.zeros((3001, 5)), np.ones(3001, int), np.zeros((3001, 2)), [],
                    None)
    assert A.frame_times(track, 20).tolist() == pytest.approx(np.arange(61) * 0.05)
    assert len(A.frame_times(track, 30, speed=0.5)) == 181
    with pytest.raises(ValueError, match="after the run's end"):
        A.frame_times(track, 20, start=4)


@pytest.mark.skipif(importlib.util.find_spec("imageio_ffmpeg") is not None, reason="imageio-ffmpeg is installed")
def test_mp4_without_imageio_ffmpeg_says_what_to_install(tmp_path, capsys):
    assert biped_sim(["animate", "--scene", "walk", "-o", str(tmp_path / "w.mp4")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["biped-sim animate: writing MP4 needs imageio-ffmpeg: pip install imageio-ffmpeg (or write a .gif)"]
    assert not (tmp_path / "w.mp4").exists()


@pytest.mark.skipif(importlib.util.find_spec("imageio_ffmpeg") is None, reason="imageio-ffmpeg is not installed")
def test_mp4_through_imageio_ffmpeg(tmp_path):
    import imageio_ffmpeg
    out = tmp_path / "w.mp4"
    assert biped_sim(["animate", "--scene", "walk", "--duration", "1", "--fps", "10", "-q", "-o", str(out)]) == 0
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    assert meta["size"] == (A.WIDTH, A.HEIGHT) and meta["fps"] == 10
    assert sum(1 for _ in reader) == 11


def _not_a_biped_bag(path):
    from mcap.writer import Writer
    path.mkdir()
    with open(path / "other_0.mcap", "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        cid = w.register_channel("/chatter", "cdr", sid)
        w.add_message(cid, log_time=1, publish_time=1, data=b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00")
        w.finish()
    return path


@pytest.mark.parametrize("case, argv, says", [
    ("missing", lambda p: [str(p / "nope")], "no bag at"),
    ("empty folder", lambda p: [str(p / "empty")], "holds no .mcap file"),
    ("not biped_sim", lambda p: [str(_not_a_biped_bag(p / "other"))], "no joint_states messages"),
    ("garbage", lambda p: [str(p / "bad" / "x.mcap")], "is not an MCAP file"),
    ("two sources", lambda p: [str(p), "--scene", "walk"], "give a BAG or --scene NAME"),
    ("no source", lambda p: [], "give a BAG or --scene NAME"),
    ("suffix", lambda p: ["--scene", "walk", "-o", str(p / "w.png")], "must end in .gif or .mp4"),
    ("speed", lambda p: ["--scene", "walk", "--speed", "0"], "--speed must be a positive number"),
    ("scene", lambda p: ["--scene", "nowhere"], "unknown scene 'nowhere'"),
])
def test_bad_input_is_one_line_and_exit_code_2(tmp_path, capsys, case, argv, says):
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "x.mcap").write_bytes(b"this is not an mcap file")
    args = ["animate", *argv(tmp_path)]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "out.gif")]
    assert biped_sim(args) == 2, case
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("biped-sim animate: error: ") and says in err[0], (case, err)
    assert not (tmp_path / "out.gif").exists()


# -- issue 34, item 2: memory that does not grow with the bag ----------------------------------------------
PEAK_RSS = r"""
import sys
from biped_sim.cli import main as biped_sim


def vm(key):   # the process's own figures (KB): VmHWM is the peak RSS since the start or the last reset
    return int(next(ln.split()[1] for ln in open("/proc/self/status") if ln.startswith(key + ":")))


warm, bag, out = sys.argv[1:4]
args = ["animate", "-o", out, "--fps", "50", "-q"] if out != "-" else ["inspect", "--no-png"]
biped_sim(args[:1] + [warm] + args[1:])     # everything imported and cached first, on a tiny bag
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")                              # resets VmHWM to the RSS now (Linux)
before = vm("VmRSS")
code = biped_sim(args[:1] + [bag] + args[1:])
print("PEAK", code, before, vm("VmHWM"))
"""


def peak_growth_kb(tool, warm, bag, tmp_path) -> tuple[int, int]:
    """(peak RSS in KB, its growth over the warmed-up process) of ``biped-sim animate`` (50 frames a
    simulated second) or ``inspect --no-png`` of ``bag``, in a fresh process (after a run on ``warm``)."""
    import subprocess
    import sys
    out = str(tmp_path / "m.gif") if tool == "animate" else "-"
    done = subprocess.run([sys.executable, "-c", PEAK_RSS, str(warm), str(bag), out], capture_output=True,
                          text=True, timeout=120, stdin=subprocess.DEVNULL)
    line = [ln for ln in done.stdout.splitlines() if ln.startswith("PEAK")]
    assert done.returncode == 0 and line, done.stdout + done.stderr
    _, code, before, after = line[0].split()
    assert code == "0", done.stdout + done.stderr
    return int(after), int(after) - int(before)


def test_animate_and_inspect_memory_does_not_grow_with_the_bag(tmp_path):
    """A 1 s and a 4 s recorded walk at 4 kHz. ``animate`` at 50 frames a simulated second kept every
    frame (peak RSS 105 and 172 MB before) and ``inspect`` every state as Python lists (87 and 102 MB,
    its growth 1.0 and 15.7 MB). Now each frame is written and let go, and the states are summed up and
    thinned as they are read: the longer bag's peak is the shorter's (89 and 89 MB; 85 and 85 MB)."""
    bags = {}
    for name, seconds in (("short", 1.0), ("long", 4.0)):
        assert biped_sim(["simulate", "--scene", "walk", "--duration", str(seconds), "--control-period", "0.00025",
                          "--record", str(tmp_path / name)]) == 0
        bags[name] = next((tmp_path / name).iterdir())
    figures = {}
    for tool in ("animate", "inspect"):
        for name in ("short", "long"):
            figures[tool, name] = peak_growth_kb(tool, bags["short"], bags[name], tmp_path)
    print({k: f"peak {v[0] / 1024:.1f} MB, growth {v[1] / 1024:.2f} MB" for k, v in figures.items()})
    (a_short, _), (a_long, _) = figures["animate", "short"], figures["animate", "long"]
    assert a_long < 1.15 * a_short, figures                    # was 1.6 times
    (_, i_short), (_, i_long) = figures["inspect", "short"], figures["inspect", "long"]
    assert i_long < 1.5 * i_short + 1024, figures              # was 15 times (1.0 and 15.7 MB)


def test_thinned_keeps_an_even_sample_of_any_length_in_bounded_memory():
    from biped_sim.recording.inspect_bag import Thinned
    for n in (7, 100, 12345):
        th = Thinned(1, capacity=100)
        for i in range(n):
            th.add([i])
        kept = th.array()[:, 0]
        assert len(kept) <= 100 and kept[0] == 0 and np.all(np.diff(kept) == th.stride)
        assert len(kept) == n if n <= 100 else len(kept) > 50 and kept[-1] > n - 2 * th.stride


def test_animate_of_a_bag_cut_short_says_so_and_where_it_ends(tmp_path, capsys):
    """(issue 34, item 5) A bag whose writer was killed is drawn up to its last complete chunk; before,
    nothing said that the animation ends early."""
    from mcap.reader import make_reader
    assert biped_sim(["simulate", "--scene", "walk", "--duration", "4", "--record", str(tmp_path / "b")]) == 0
    mcap = next((tmp_path / "b").glob("*/*.mcap"))
    with open(mcap, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) >= 2
    size = chunks[-1].chunk_start_offset + 100              # inside the last chunk: what a SIGKILL leaves
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / mcap.name).write_bytes(mcap.read_bytes()[:size])
    capsys.readouterr()
    assert biped_sim(["animate", str(cut), "-o", str(tmp_path / "cut.gif"), "-q"]) == 0
    err = capsys.readouterr().err
    assert f"the bag is CUT SHORT at {size} bytes" in err, err
    end = chunks[-2].message_end_time / 1e9
    assert f"drawn up to its last complete chunk, t = {end:.6g} s" in err and f"biped-sim recover {cut}" in err, err
    frames, _ = gif_frames(tmp_path / "cut.gif")
    assert len(frames) == int(end * 20 + 1e-9) + 1 < 81          # up to the cut, not the whole 4 s at 20 fps


def test_a_frame_draws_rabbits_legs_through_its_knees():
    """Issue 31, item 3: RABBIT (five links) at a given q, no simulation: the pixels along each tibia (knee
    to foot, from the description's forward kinematics) are that leg's colour, and the torso's are drawn."""
    from biped_sim.config.models import load_model
    rabbit = load_model("rabbit")
    q = np.array([0.1, 0.75, 3.5, 2.7, 0.5, 0.1, 0.2])       # legs apart, knee 1 bent
    track = A.Track(np.zeros(1), q[None, :], np.ones(1, int), np.array([[0.0, 300.0]]), [], rabbit)
    drawer = A.FrameDrawer(track)
    frame = np.asarray(drawer.draw(0.0, q, 1, (0.0, 300.0)).convert("RGB"))
    seg = rabbit.segments(q)                                  # (links, joint/tip, xy): femur_1, femur_2, tibia_1, ...
    cx, cy = q[0], MK.ground_y(q[0], 0.0) + 0.75

    def pixel(p):
        return frame[int(round(A.HEIGHT / 2 - (p[1] - cy) * A.PIXELS_PER_METRE)),
                     int(round(A.WIDTH / 2 + (p[0] - cx) * A.PIXELS_PER_METRE))]
    for link, colour in ((2, MK.LEG_COLOURS[1]), (3, MK.LEG_COLOURS[2]), (4, MK.TORSO_COLOUR)):
        start, end = seg[link]                                # a tibia from its knee; the torso from the hip
        for s in (0.3, 0.5, 0.7):                             # along the link, away from the dots at its ends
            rgb = [round(255 * c) for c in colour[:3]]
            assert pixel(start + s * (end - start)).tolist() == rgb, (link, s)
