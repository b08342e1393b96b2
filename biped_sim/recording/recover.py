"""``recover``: a bag whose writer was killed (SIGKILL, power loss) rewritten into a clean one.

Owns the repair of a bag cut short: its MCAP has every chunk written before the kill (the writer
process ends a chunk at least every 0.5 s) but no summary, and there is no metadata.yaml. The bag
is rewritten by the same writer and ended by the same ``finish_bag`` as a recording, so a recovered
bag has the layout of one that was closed (``biped-sim recover``).
"""
from __future__ import annotations

import os
from pathlib import Path

from biped_sim.config.command_errors import CommandError
from biped_sim.recording import bagio
from biped_sim.recording.bagformat import PROFILE


def kept_name(src: Path) -> Path:
    """A free name for the original of ``src``: ``<name>.truncated``, else ``<name>.truncated.1``, ... ."""
    kept = src.with_name(src.name + ".truncated")
    n = 0
    while kept.exists():
        n += 1
        kept = src.with_name(f"{src.name}.truncated.{n}")
    return kept


def write_missing_metadata(bag_dir: Path, src: Path) -> dict:
    """A complete MCAP whose ``metadata.yaml`` could not be written at the end of the recording (its
    folder became read-only, or full, before the close): ``metadata.yaml`` from the MCAP's summary,
    the MCAP unchanged. Returns recover's dict, ``kept`` None (no file replaced)."""
    import yaml
    from mcap.reader import make_reader

    from biped_sim.recording.bagformat import bag_metadata, write_metadata_yaml
    with open(src, "rb") as f:
        summary = make_reader(f).get_summary()
    stats = summary.statistics
    counts = stats.channel_message_counts if stats else {}
    topics = [dict(name=c.topic, type=summary.schemas[c.schema_id].name if c.schema_id in summary.schemas else "",
                   qos=yaml.safe_load(c.metadata.get("offered_qos_profiles", "")) or [],
                   hash=c.metadata.get("topic_type_hash", ""), count=counts.get(c.id, 0))
              for c in summary.channels.values()]
    info = bag_metadata(src.name, topics, stats.message_start_time if stats else 0,
                        stats.message_end_time if stats else 0)
    try:
        write_metadata_yaml(bag_dir, info)
    except OSError as exc:
        raise OSError(exc.errno, f"cannot write {bag_dir / 'metadata.yaml'} ({exc.strerror}): make the bag's "
                                 "folder writable, then run biped-sim recover again; nothing was changed") from None
    return dict(path=str(src), kept=None, messages=sum(t["count"] for t in topics), end="",
                topics={t["name"]: t["count"] for t in topics})


def recover(bag_dir, compression="zstd") -> dict:
    """Rewrite a bag's MCAP cut short (SIGKILL, power loss) into a clean one; regenerate metadata.yaml.

    Reads records in file order until the first incomplete one: every chunk written before the
    kill is kept (CRC-checked). The original file is kept under a free name (:func:`kept_name`),
    never over an earlier one. Returns dict(path, kept, messages, topics={topic: count}, end=why
    the original ended). Refuses, changing nothing: a file that is not MCAP or has no complete
    message (ValueError), a file a bag writer holds right now, and a complete bag (CommandError).
    A complete MCAP without ``metadata.yaml`` (its folder became unwritable before the close) gets
    its ``metadata.yaml`` (:func:`write_missing_metadata`).
    """
    import yaml
    from mcap.records import Channel, Chunk, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    from biped_sim.recording.mcapfile import McapFileWriter
    from biped_sim.recording.writer import finish_bag
    bag_dir = Path(bag_dir)
    if bag_dir.is_file():       # the bag's .mcap: its folder is the bag (metadata.yaml is written there)
        if bag_dir.suffix != ".mcap":
            raise ValueError(f"{bag_dir} is not a bag's .mcap file: give the bag directory")
        bag_dir = bag_dir.parent
    src = bagio.mcap_path(bag_dir)          # ValueError: no bag, or not MCAP
    if bagio.being_written(src):
        raise CommandError(f"{src} is being recorded right now (a bag writer holds it): wait until the "
                           "recording ends; nothing was changed")
    if not bagio.cut_short(src):
        # a biped_sim bag whose folder became unwritable before the close (another program's MCAP is no
        # bag of ours to complete)
        if not (bag_dir / "metadata.yaml").is_file() and "biped_sim" in bagio.read_metadata(src):
            return write_missing_metadata(bag_dir, src)
        raise CommandError(f"nothing to recover: {src} is complete (it has its summary); nothing was changed")
    schemas, channels, metadata, messages = {}, {}, [], []
    problem = ""

    def take(rec):
        if isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            channels[rec.id] = rec
        elif isinstance(rec, Message):
            messages.append(rec)

    with open(src, "rb") as f:
        reader = StreamReader(f, emit_chunks=True, validate_crcs=True)
        try:
            for rec in reader.records:
                if isinstance(rec, Chunk):
                    for r in breakup_chunk(rec, validate_crc=True):
                        take(r)
                elif isinstance(rec, Metadata):
                    if rec.name != "rosbag2":          # written anew below
                        metadata.append(rec)
                else:
                    take(rec)
        except Exception as exc:  # noqa: BLE001 - the truncated tail
            problem = f"{type(exc).__name__}: {exc}" if str(exc) else f"{type(exc).__name__} (cut at {f.tell()} bytes)"
    if not messages:
        raise CommandError(f"nothing to recover: {src} holds no complete message ({bagio.cut_short(src)}); "
                           "nothing was changed")
    # the clean file is written beside the original first, then the original is kept under a free
    # name and the clean one takes its place: at every moment both are on disk
    tmp = src.with_name(src.name + ".recovering")
    try:
        with open(tmp, "wb") as out:
            w = McapFileWriter(out, PROFILE, "biped_sim recover (mcap python records)", compression=compression)
            for m in metadata:
                w.add_metadata(m.name, m.metadata)
            schema_of = {s.id: w.add_schema(s.name, s.encoding, s.data) for s in schemas.values()}
            topics, channel_of = {}, {}
            for c in channels.values():
                channel_of[c.id] = w.add_channel(c.topic, c.message_encoding, schema_of.get(c.schema_id, 0), c.metadata)
                topics[channel_of[c.id]] = dict(
                    name=c.topic, type=schemas[c.schema_id].name if c.schema_id in schemas else "",
                    qos=yaml.safe_load(c.metadata.get("offered_qos_profiles", "")) or [],
                    hash=c.metadata.get("topic_type_hash", ""))
            for m in messages:
                if m.channel_id in channel_of:
                    w.add_message(channel_of[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
            info = finish_bag(w, out, bag_dir, src.name, topics)
    except BaseException:
        tmp.unlink(missing_ok=True)      # the original is untouched
        raise
    kept = kept_name(src)
    try:
        os.link(src, kept)           # the original under its kept name, and still in place
    except OSError:                  # a file system without hard links: move it (kept is a free name)
        os.replace(src, kept)
    os.replace(tmp, src)
    return dict(path=str(src), kept=str(kept), messages=len(messages), end=problem,
                topics={t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]})
