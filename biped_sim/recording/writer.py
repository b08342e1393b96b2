"""The bag writer process: frames from the recording process on stdin -> the bag's MCAP file.

Owns the reading of the frames that :class:`biped_sim.recording.recorder.BagRecorder` sends (their
protocol: :mod:`biped_sim.recording.frames`) and the end of a bag (the ``rosbag2`` record, the
summary, ``metadata.yaml``), which :func:`biped_sim.recording.recover.recover` shares. This process
numbers each topic's messages 1, 2, ... The end of the input without ``C`` (the recording process
died, even by SIGKILL) closes the bag the same way as ``C``.

Started by ``BagRecorder`` as ``python -m biped_sim.recording.writer BAG_DIR MCAP_NAME COMPRESSION
CHUNK_SIZE FLUSH_INTERVAL [MODULE:CLASS]`` (the last: another file writer, for the recording
benchmark); writes status lines (JSON) on stdout: ``{"ready": true}`` once started (imports done, the
file open), ``{"error": ...}`` at once when writing fails, ``{"done": true, "counts": {topic: n},
"error": ...}`` at the end.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from biped_sim.recording.bagformat import PROFILE, bag_metadata, channel_metadata, rosbag2_record, write_metadata_yaml
from biped_sim.recording.bagio import lock_for_writing
from biped_sim.recording.frames import FRAME, MESSAGES, add_numbered

LIBRARY = "biped_sim recorder (mcap python records)"


def finish_bag(mcap, f, bag_dir: Path, mcap_name: str, topics: dict) -> dict:
    """End a bag: the last chunk, the ``rosbag2`` record, the summary; fsync; then ``metadata.yaml``.

    ``mcap``: the McapFileWriter of the open file ``f``; ``topics``: {channel id: dict(name, type,
    qos, hash)}. metadata.yaml comes last, so that a bag that has one is complete on disk. Returns the
    ``rosbag2_bagfile_information`` mapping.
    """
    mcap.flush()             # the last chunk ends first: the rosbag2 record counts every message in the file
    info = bag_info(mcap, mcap_name, topics)
    mcap.add_metadata("rosbag2", rosbag2_record(info))
    mcap.finish()
    os.fsync(f.fileno())
    try:
        write_metadata_yaml(bag_dir, info)
    except OSError as exc:
        # the MCAP is whole (written through its open file); only its folder refuses a new file
        raise MetadataNotWritten(f"the bag's MCAP is complete but its metadata.yaml could not be written "
                                 f"({exc.strerror or exc}): make {bag_dir} writable (or free space), then run "
                                 f"'biped-sim recover {bag_dir}' to write it") from None
    return info


class MetadataNotWritten(OSError):
    """A bag complete but for its metadata.yaml (``biped-sim recover`` writes it)."""


def bag_info(mcap, mcap_name: str, topics: dict) -> dict:
    """The ``rosbag2_bagfile_information`` of the messages in the chunks ``mcap`` has ended so far."""
    counts = mcap.message_counts
    return bag_metadata(mcap_name, [dict(t, count=counts.get(cid, 0)) for cid, t in topics.items()],
                        mcap.message_start_time or 0, mcap.message_end_time or 0)


def add_topic(mcap, info: dict, schemas: dict) -> int:
    """Register a topic (a ``T`` frame's dict) in the MCAP: its schema once per type, then its channel."""
    if info["type"] not in schemas:
        schemas[info["type"]] = mcap.add_schema(info["type"], "ros2msg", info["definition"].encode())
    return mcap.add_channel(info["name"], "cdr", schemas[info["type"]], channel_metadata(info["qos"], info["hash"]))


def write_frames(inp, f, path: Path, mcap_name: str, compression="zstd", chunk_size=1024 * 1024,
                 flush_interval=0.5, report=lambda **kw: None, file_writer=None) -> int:
    """Read frames from ``inp`` into the MCAP file ``f`` until ``C`` or the end of the input; finish the bag.

    Closes a chunk at least every ``flush_interval`` s of wall time while messages come, so that a
    SIGKILL of this process loses at most that much. Returns 0, or 1 if writing failed
    (``report(error=...)`` says why at once). ``file_writer``: the class that writes the MCAP file,
    :class:`~biped_sim.recording.mcapfile.McapFileWriter` by default (the benchmark passes others).
    """
    if file_writer is None:
        from biped_sim.recording.mcapfile import McapFileWriter as file_writer
    mcap = file_writer(f, PROFILE, LIBRARY, compression=compression, chunk_size=chunk_size)
    report(ready=True)       # started: the recording process may begin its run (BagRecorder.wait_ready)
    topics, schemas = {}, {}
    channel, sequence = {}, {}      # by the recorder's topic id: the MCAP channel id, the last sequence number
    error = None
    dirty = False
    last_flush = time.monotonic()
    read, frame = inp.read, FRAME
    add_records = getattr(mcap, "add_records", None) or (    # file writers of the benchmark have no add_records
        lambda payload, channels, sequences: add_numbered(mcap.add_message, payload, channels, sequences))
    while True:
        head = read(frame.size)
        if len(head) < frame.size:
            break                     # end of input: the recording process closed or died
        kind, n = frame.unpack(head)
        payload = read(n) if n else b""
        if len(payload) < n or kind == b"C":
            break
        if error is not None:
            continue
        try:
            if kind == MESSAGES:
                try:
                    add_records(payload, channel, sequence)
                except KeyError as exc:
                    raise ValueError(f"unknown topic id {exc}: written before add_topic") from None
                dirty = True
            elif kind == b"T":
                info = json.loads(payload)
                cid = channel[info["id"]] = add_topic(mcap, info, schemas)
                sequence[info["id"]] = 0
                topics[cid] = {k: info[k] for k in ("name", "type", "qos", "hash")}
            elif kind == b"P":
                mcap.add_metadata("biped_sim", json.loads(payload))
                f.flush()
            now = time.monotonic()
            if dirty and now - last_flush >= flush_interval:
                mcap.flush()              # close the chunk: everything so far survives a SIGKILL
                dirty = False
                last_flush = now
        except Exception as exc:  # noqa: BLE001 - e.g. the disk is full
            error = f"{type(exc).__name__}: {exc}"
            report(error=error)
    info = None
    try:
        if error is None:
            info = finish_bag(mcap, f, path, mcap_name, topics)
        else:   # the MCAP stays without summary (recover repairs it); metadata.yaml counts what is on disk
            f.flush()
            write_metadata_yaml(path, info := bag_info(mcap, mcap_name, topics))
    except MetadataNotWritten as exc:
        error = error or str(exc)
        report(error=error)
    except Exception as exc:  # noqa: BLE001
        error = error or f"{type(exc).__name__}: {exc}"
        report(error=error)
    counts = None if info is None else {
        t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    report(done=True, counts=counts, error=error)
    return 1 if error else 0


def main(argv=None) -> int:
    """The writer process (see the module docstring)."""
    import signal
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) not in (5, 6):
        print("usage: python -m biped_sim.recording.writer BAG_DIR MCAP_NAME COMPRESSION CHUNK_SIZE "
              "FLUSH_INTERVAL [MODULE:CLASS of the file writer] (started by BagRecorder)", file=sys.stderr)
        return 2
    path, mcap_name, compression, chunk_size, flush_interval = argv[:5]
    file_writer = None
    if len(argv) == 6:
        import importlib
        module, _, name = argv[5].partition(":")
        file_writer = getattr(importlib.import_module(module), name)
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # the recording process decides when to stop
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        os.nice(10)       # on a busy machine the simulation gets the CPU first; the writer catches up
    except OSError:
        pass
    status = sys.stdout

    def report(**kw):
        try:
            status.write(json.dumps(kw) + "\n")
            status.flush()
        except OSError:
            pass
    path = Path(path)
    with open(path / mcap_name, "wb") as f:
        lock_for_writing(f)      # held until the bag is finished: recover refuses a file being written
        return write_frames(sys.stdin.buffer, f, path, mcap_name, compression, int(chunk_size),
                            float(flush_interval), report, file_writer)


if __name__ == "__main__":
    sys.exit(main())
