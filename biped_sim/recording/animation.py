"""A run as a moving picture: the stick figure, the ground force arrow, a time stamp (``biped-sim animate``).

Owns the frames (drawn with Pillow's ImageDraw, much faster than the same figure in matplotlib: the
figures in docs/cli.md) and the files (GIF through Pillow, MP4 through imageio-ffmpeg
when it is installed). A run comes from a bag (:func:`track_from_bag`) or from a headless
``simulate`` (:func:`track_from_result`); the points are :mod:`biped_sim.engine.drawing`'s (any chain)
and the arrow scale, colours and impact flash those of the markers (:mod:`biped_sim.recording.markers`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from biped_sim.config.progress import Progress
from biped_sim.recording import markers as MK

WIDTH, HEIGHT = 560, 320          # pixels (multiples of 16: an MP4 encoder takes them as they are)
PIXELS_PER_METRE = 130.0
MP4_MISSING = "writing MP4 needs imageio-ffmpeg: pip install imageio-ffmpeg (or write a .gif)"


@dataclass
class Track:
    """A run's states over time: t (k), q (k, N) the model's coordinates, stance leg (k), ground force (k, 2);
    impacts (time, (x, y) of the landing foot); the model and the ground slope."""
    t: np.ndarray
    q: np.ndarray
    leg: np.ndarray
    force: np.ndarray
    impacts: list
    model: object
    slope: float = 0.0


def track_from_result(result, model, slope=0.0) -> Track:
    """The Track of a ``SimulationResult`` (``simulate`` or ``Scene.simulate``) of ``model``'s robot."""
    impacts = [(e.time, foot) for e in result.impacts if (foot := _landing_foot(model, e.q, e.leg)) is not None]
    return Track(result.t, result.q, result.stance_leg, result.grf, impacts, model, slope)


def _landing_foot(model, q, foot, drawing=None):
    """(x, y) of foot ``foot`` at the impact state ``q`` (a state of the model's N coordinates), or None for
    an impact without one (a state left empty, of another size, or a foot the robot does not have)."""
    from biped_sim.engine.drawing import RobotDrawing
    from biped_sim.engine.figure import coordinate_count
    feet = len(getattr(model, "contacts", (1, 2)))        # a BipedModel's two feet, a description's contacts
    if q is None or foot not in range(1, feet + 1) or len(q) != coordinate_count(model):
        return None
    q = np.asarray(q, dtype=float)
    if not np.all(np.isfinite(q)):
        return None
    return tuple(float(v) for v in (drawing or RobotDrawing(model)).foot(q, foot))


def track_from_bag(bag) -> Track:
    """The Track of a biped_sim bag (joint_states, ground_reaction, impact); ValueError in one line
    for a path that is not such a bag."""
    from biped_sim.recording import inspect_bag
    try:
        run = inspect_bag.load_run(bag)
    except ValueError:
        raise
    except Exception as exc:  # noqa: BLE001 - mcap's reader raises many kinds for a file that is not a bag
        raise ValueError(f"cannot read {bag} as an MCAP bag: {type(exc).__name__}: {exc}") from None
    if not len(run["t"]):
        raise ValueError(f"{bag} has no joint_states messages: not a biped_sim run (or an empty one); "
                         f"topics: {sorted(run['counts']) or 'none'}")
    params = run["params"] or {}
    model = run["robot"].model()        # ValueError, one line: a robot that cannot be loaded is not drawn
    # the ground force has its own messages (in stance only), stamped like the state they belong to
    by_ns = dict(zip(np.round(run["grf_t"] * 1e9).astype(np.int64).tolist(), run["grf"].tolist()))
    force = np.array([by_ns.get(k, (0.0, 0.0)) for k in np.round(run["t"] * 1e9).astype(np.int64).tolist()])
    impacts = []
    for e in run["impacts"]:
        at = _landing_foot(model, e.get("q") if isinstance(e.get("q"), list) else None, e.get("foot"))
        if at is not None:
            impacts.append((float(e["time"]), at))
    return Track(run["t"], run["q"], run["leg"], force.reshape(-1, 2), impacts, model,
                 float(params.get("slope", 0.0) or 0.0))


def frame_times(track: Track, fps: float, speed: float = 1.0, start: float | None = None,
                duration: float | None = None) -> np.ndarray:
    """The simulated times of the frames: one every ``speed / fps`` s from ``start`` (default: the
    first state) over ``duration`` (default: to the last state)."""
    t0, step, n = frame_grid(track.t[0], track.t[-1], fps, speed, start, duration)
    return t0 + np.arange(n) * step


def frame_grid(t_first: float, t_last: float, fps: float, speed: float = 1.0, start: float | None = None,
               duration: float | None = None) -> tuple[float, float, int]:
    """(time of the first frame, time between frames, number of frames) of a run whose states span
    ``t_first .. t_last`` (see :func:`frame_times`); frame k is at ``t0 + k * step``."""
    t0 = t_first if start is None else max(float(start), t_first)
    t1 = t_last if duration is None else min(t0 + float(duration), t_last)
    if t0 > t_last:
        raise ValueError(f"--start {start} is after the run's end (t = {t_last:.6g} s)")
    n = max(1, int(math.floor((t1 - t0) * fps / speed + 1e-9)) + 1)
    return t0, speed / fps, n


_PALETTE = {"background": (255, 255, 255), "ground": (77, 77, 77), "tick": (190, 190, 190), "text": (0, 0, 0)}


def _rgb(colour):
    return tuple(int(round(255 * c)) for c in colour[:3])


class FrameDrawer:
    """Draws one state on a WIDTH x HEIGHT palette image; the view follows the hip."""

    def __init__(self, track: Track, width=WIDTH, height=HEIGHT, scale=PIXELS_PER_METRE):
        from PIL import ImageFont

        from biped_sim.engine.drawing import RobotDrawing
        self.track, self.w, self.h, self.s = track, width, height, scale
        self.drawing = RobotDrawing(track.model)     # any chain: its description's links (drawing.py)
        colours = [_PALETTE["background"], _PALETTE["ground"], _PALETTE["tick"], _PALETTE["text"]] + [
            _rgb(c) for c in (MK.LEG_COLOURS[1], MK.LEG_COLOURS[2], MK.TORSO_COLOUR, MK.HIP_COLOUR,
                              MK.STANCE_FOOT_COLOUR, MK.SWING_FOOT_COLOUR, MK.FORCE_COLOUR, MK.FLASH_COLOUR)]
        self.index = {rgb: i for i, rgb in enumerate(colours)}
        self.palette = [v for rgb in colours for v in rgb] + [0] * (768 - 3 * len(colours))
        self.font = ImageFont.load_default(size=15)
        self.small = ImageFont.load_default(size=11)

    def _c(self, colour):
        return self.index[_rgb(colour) if len(colour) == 4 else colour]

    def draw(self, t, q, leg, force, flash_at=None):
        from PIL import Image, ImageDraw
        img = Image.new("P", (self.w, self.h), 0)
        img.putpalette(self.palette)
        d = ImageDraw.Draw(img)
        fig = self.drawing.figure(q)
        slope = self.track.slope
        cx, cy = fig.hip[0], MK.ground_y(fig.hip[0], slope) + 0.75   # view centre (m)

        def px(p):
            return (self.w / 2 + (p[0] - cx) * self.s, self.h / 2 - (p[1] - cy) * self.s)
        half = self.w / 2 / self.s + 0.5
        x0, x1 = cx - half, cx + half
        for k in range(math.floor(x0 / 0.5), math.ceil(x1 / 0.5) + 1):   # a tick every 0.5 m: the motion
            x = k * 0.5
            a, b = px((x, MK.ground_y(x, slope))), px((x, MK.ground_y(x, slope) - 0.06))
            d.line([a, b], fill=self.index[_PALETTE["tick"]], width=2)
        d.line([px((x0, MK.ground_y(x0, slope))), px((x1, MK.ground_y(x1, slope)))],
               fill=self.index[_PALETTE["ground"]], width=2)
        if flash_at is not None:
            self._dot(d, px(flash_at), 14, MK.FLASH_COLOUR)
        self._lines(d, px, fig.body, self._c(MK.TORSO_COLOUR), 6)
        for k, lines in enumerate(fig.legs, start=1):
            self._lines(d, px, lines, self._c(MK.LEG_COLOURS[2 - k % 2]), 5)
        for k, foot in enumerate(fig.feet, start=1):
            self._dot(d, px(foot), 6 if k == leg else 4, MK.STANCE_FOOT_COLOUR if k == leg else MK.SWING_FOOT_COLOUR)
        self._dot(d, px(fig.hip), 6, MK.HIP_COLOUR)
        if 1 <= leg <= len(fig.feet) and (force[0] or force[1]):
            foot = fig.feet[leg - 1]
            self._arrow(d, px(foot), px(MK.force_arrow_end(foot, force)), self._c(MK.FORCE_COLOUR))
        text = self.index[_PALETTE["text"]]
        d.text((10, 8), f"t = {t:6.3f} s", fill=text, font=self.font)
        d.text((10, self.h - 20), f"ground force arrow: {MK.NEWTONS_PER_METRE:g} N per m", fill=text,
               font=self.small)
        return img

    @staticmethod
    def _lines(d, px, lines, fill, width):
        """A polyline (``lines.strip``) or its segments, as the markers draw them."""
        points = [px(p) for p in lines.points]
        if lines.strip:
            if len(points) > 1:
                d.line(points, fill=fill, width=width, joint="curve" if len(points) > 2 else None)
        else:
            for a, b in zip(points[::2], points[1::2]):
                d.line([a, b], fill=fill, width=width)

    def _dot(self, d, p, r, colour):
        d.ellipse([p[0] - r, p[1] - r, p[0] + r, p[1] + r], fill=self._c(colour))

    @staticmethod
    def _arrow(d, a, b, fill):
        d.line([a, b], fill=fill, width=3)
        ang = math.atan2(b[1] - a[1], b[0] - a[0])
        head = [(b[0] - 10 * math.cos(ang + s), b[1] - 10 * math.sin(ang + s)) for s in (0.45, -0.45)]
        d.polygon([b, *head], fill=fill)


def frames(track: Track, times, progress=None):
    """Yield the Pillow image of each frame time (the last state at or before it)."""
    drawer = FrameDrawer(track)
    idx = np.clip(np.searchsorted(track.t, times, side="right") - 1, 0, len(track.t) - 1)
    impact_t = np.array([i[0] for i in track.impacts])
    for n, (tk, i) in enumerate(zip(times, idx)):
        flash = None
        if len(impact_t):
            j = int(np.searchsorted(impact_t, tk, side="right")) - 1
            if j >= 0 and tk - impact_t[j] <= MK.FLASH_DURATION:
                flash = track.impacts[j][1]
        yield drawer.draw(tk, track.q[i], int(track.leg[i]), track.force[i], flash)
        if progress is not None:
            progress(n + 1, len(times))


def check_output(path) -> str:
    """"gif" or "mp4" for an output path; ValueError for another suffix or MP4 without imageio-ffmpeg."""
    suffix = str(path).rsplit(".", 1)[-1].lower() if "." in str(path) else ""
    if suffix not in ("gif", "mp4"):
        raise ValueError(f"the output must end in .gif or .mp4, got {path}")
    if suffix == "mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise MissingEncoder(MP4_MISSING) from None
    return suffix


class MissingEncoder(ValueError):
    """MP4 asked for, imageio-ffmpeg not installed."""


def gif_fps(fps: float) -> float:
    """The frame rate a GIF can keep: its delays are whole hundredths of a second (at least 2: browsers
    slow down shorter ones), so 30 fps becomes 33.3 fps, and the speed stays exact."""
    return 100.0 / max(2, round(100.0 / fps))


def write(track: Track, path, fps=20.0, speed=1.0, start=None, duration=None, progress=None):
    """Write the animation to ``path`` (.gif or .mp4); returns (number of frames, frame rate used)."""
    kind = check_output(path)
    if kind == "gif":
        fps = gif_fps(fps)
    times = frame_times(track, fps, speed, start, duration)
    write_frames(frames(track, times, progress), path, kind, fps)
    return len(times), fps


def write_frames(images, path, kind, fps):
    """Write the images (an iterable, consumed one at a time) as a GIF or an MP4 at ``fps``.

    Each frame is encoded and let go before the next is drawn: the memory does not grow with the
    number of frames (Pillow's ``save_all`` keeps every frame until the end: 0.4 MB a frame, 2.4 GB
    for a 273 s run at 20 fps)."""
    if kind == "gif":
        with GifStream(path, fps) as gif:
            for img in images:
                gif.add(img)
        return
    import imageio_ffmpeg
    writer = imageio_ffmpeg.write_frames(str(path), (WIDTH, HEIGHT), fps=fps, quality=7)
    writer.send(None)
    try:
        for img in images:
            writer.send(img.convert("RGB").tobytes())
    finally:
        writer.close()


class GifStream:
    """A looping GIF written one frame at a time (Pillow's public ``GifImagePlugin.getheader`` and
    ``getdata``), all frames on the first frame's palette (the drawer's, the same in every frame).
    A frame after the first is written as the rectangle that changed since the one before (as Pillow's
    ``save_all`` does), so only the previous frame is kept."""

    def __init__(self, path, fps):
        self.path, self.delay_ms = path, round(1000 / fps)
        self.previous = None
        self.file = open(path, "wb")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def add(self, img):
        from PIL import GifImagePlugin, ImageChops
        if self.previous is None:
            header, _used = GifImagePlugin.getheader(img, None, {"loop": 0, "optimize": False})
            self.file.write(b"".join(header))
            box = (0, 0) + img.size
        else:
            box = ImageChops.difference(self.previous, img).getbbox() or (0, 0, 1, 1)
        part = img if box == (0, 0) + img.size else img.crop(box)
        self.file.write(b"".join(GifImagePlugin.getdata(part, offset=box[:2], duration=self.delay_ms)))
        self.previous = img

    def close(self):
        if not self.file.closed:
            self.file.write(b";")           # the GIF trailer
            self.file.close()


def write_bag(bag, path, fps=20.0, speed=1.0, start=None, duration=None, progress=None):
    """Write the animation of a biped_sim bag to ``path`` reading the bag as a stream (the memory does
    not grow with the bag); returns (number of frames, frame rate used, BagStates of the bag: its
    times, whether it is cut short)."""
    kind = check_output(path)
    if kind == "gif":
        fps = gif_fps(fps)
    states = BagStates(bag)
    t0, step, n = frame_grid(states.t_first, states.t_last, fps, speed, start, duration)
    write_frames(states.frames(t0, step, n, progress), path, kind, fps)
    return n, fps, states


class BagStates:
    """The states of a biped_sim bag read as a stream: first ``t_first``/``t_last`` (seconds; a pass
    over the joint_states without decoding them), then :meth:`frames` (a second pass). ``cut``: why
    the file is incomplete ('' if whole; it is read up to its last complete chunk)."""

    def __init__(self, bag):
        from biped_sim.recording import bagio, messages as M
        from biped_sim.recording.bag_robot import bag_robot
        self.bag = bag
        try:
            topics = bagio.channels(bag)
            self.cut = bagio.cut_short(bag)
            self.being_written = bool(self.cut) and bagio.being_written(bag)
            self.t_js = bagio.find_topic(topics, "joint_states")
            self.t_grf = bagio.find_topic(topics, "ground_reaction")
            self.t_imp = bagio.find_topic(topics, "impact")
            first = last = None
            count = 0
            if self.t_js is not None:
                for _topic, _typ, t_ns, _data in bagio.messages(bag, topics=[self.t_js]):
                    first = t_ns if first is None else first
                    last, count = t_ns, count + 1
        except ValueError:
            raise
        except Exception as exc:  # noqa: BLE001 - mcap's reader raises many kinds for a file that is not a bag
            raise ValueError(f"cannot read {bag} as an MCAP bag: {type(exc).__name__}: {exc}") from None
        if not count:
            raise ValueError(f"{bag} has no joint_states messages: not a biped_sim run (or an empty one); "
                             f"topics: {sorted(topics) or 'none'}")
        self.count, self.t_first, self.t_last = count, first / 1e9, last / 1e9
        try:
            params = bagio.run_parameters(bag)
        except ValueError:
            params = None
        names = ()
        for _topic, typ, _t, data in bagio.messages(bag, topics=[self.t_js]):
            names = M.joint_state_names_cdr(typ, data)
            break
        # the robot the bag recorded, drawn from its links (ValueError, one line, when it cannot be loaded)
        self.model = bag_robot(params, names).model()
        self.slope = float((params or {}).get("slope", 0.0) or 0.0)

    def frames(self, t0, step, n, progress=None):
        """Yield the image of frame k (time ``t0 + k * step``, k < n): the last state at or before it,
        drawn as :func:`frames` draws a Track."""
        from biped_sim.recording import bagio, messages as M
        drawer = FrameDrawer(Track(None, None, None, None, [], self.model, self.slope))
        impacts = []                  # (time, landing foot position), pruned as the frames pass them
        k = 0
        state = None                  # (t_ns, q, leg, force) of the last state before the next frame
        grf = (None, (0.0, 0.0))      # the last ground force (stamp ns, force): it follows its state

        def draw_until(t_next):
            nonlocal k
            while k < n and (t_next is None or t0 + k * step < t_next):
                tk = t0 + k * step
                while len(impacts) > 1 and impacts[1][0] <= tk:
                    impacts.pop(0)
                flash = impacts[0][1] if impacts and impacts[0][0] <= tk <= impacts[0][0] + MK.FLASH_DURATION \
                    else None
                t_ns, q, leg, force = state
                yield drawer.draw(tk, q, leg, grf[1] if grf[0] == t_ns else force, flash)
                k += 1
                if progress is not None:
                    progress(k, n)

        topics = [t for t in (self.t_js, self.t_grf, self.t_imp) if t is not None]
        for topic, typ, _t, data in bagio.messages(self.bag, topics=topics):
            msg = bagio.decode(typ, data)
            if topic == self.t_js:
                t_ns, q, _dq, _u, leg = M.joint_state_values(msg)
                if state is not None:
                    yield from draw_until(t_ns / 1e9)
                    if k >= n:
                        return
                state = (t_ns, np.array(q), leg, (0.0, 0.0))
            elif topic == self.t_grf:
                t_ns, force, _leg = M.wrench_values(msg)
                grf = (t_ns, tuple(force))
            else:
                for e in M.event_values(msg):
                    q = e.get("q") if isinstance(e.get("q"), list) else None
                    at = _landing_foot(self.model, q, e.get("foot"), drawer.drawing)
                    if at is not None:
                        impacts.append((float(e["time"]), at))
                impacts.sort(key=lambda i: i[0])
        if state is not None:
            yield from draw_until(None)


class ProgressBar:
    """``progress(done, total)`` of the frames drawn (config.progress: a bar on a terminal, a line every
    10 % or 10 s elsewhere); it ends itself at the last frame."""

    def __init__(self, label="animate", stream=None):
        self.label, self.stream, self.display = label, stream, None

    def __call__(self, done, total):
        if self.display is None:
            self.display = Progress(total, self.label, unit="frames", stream=self.stream)
        self.display.update(done)
        if done >= total:
            self.display.close()
