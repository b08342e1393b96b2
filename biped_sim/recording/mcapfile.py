"""An MCAP file writer (https://mcap.dev/spec) on mcap's public record classes, fast per message.

Owns the layout of our MCAP files: the magic and Header; a data section of compressed Chunks (each
holding the Schema and Channel records registered while it was open, then Message records),
each followed by its MessageIndex records, and Metadata records between chunks; DataEnd; a summary
section (Schemas, Channels, Statistics, ChunkIndexes, MetadataIndexes, SummaryOffsets); Footer and
magic. That is the layout ``mcap.writer.Writer`` writes; ``mcap``'s public readers and ``rosbags``
read it (test/integration/test_recorder.py).

Why not ``mcap.writer.Writer`` itself: its public ``add_message`` builds a ``Message`` dataclass and
writes its fields one call at a time; the recorder's writer process, which spends its time adding
messages, then needs more CPU per message than with this writer (``python -m benchmarks.bench_record``;
the figures in docs/recording.md). Every record other than
Message is built by ``mcap.records`` (public API); the Message record (opcode 0x05: channel id u16,
sequence u32, log time u64, publish time u64, data) is the one record packed here.

``flush()`` ends the chunk in progress and flushes the file: what was added before survives a
SIGKILL of the process, and :func:`biped_sim.recording.recover.recover` rebuilds the summary.
"""
from __future__ import annotations

import array
import struct
import sys
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from biped_sim.recording.frames import add_numbered, append_messages

MAGIC = b"\x89MCAP0\r\n"
#: the Message record: opcode, record length, channel id, sequence, log time, publish time (then data)
MESSAGE_RECORD = struct.Struct("<BQHIQQ")
_MESSAGE_INDEX_HEAD = struct.Struct("<BQHI")   # opcode, record length, channel id, records' byte length
_INDEX_PAIR = struct.Struct("<QQ")            # a MessageIndex entry: log time, offset in the chunk
_MESSAGE_FIELDS = MESSAGE_RECORD.size - 9      # the record length counts what follows opcode + length
_FOOTER_START = struct.Struct("<BQQQ")         # the footer's bytes that its summary CRC covers


def _compressor(compression: str):
    """(chunk's compression name, bytes -> compressed bytes) for "zstd", "lz4" or "none"."""
    if compression == "zstd":
        import zstandard
        return "zstd", zstandard.compress            # level 3, as mcap's writer compresses
    if compression == "lz4":
        import lz4.frame
        return "lz4", lz4.frame.compress
    if compression == "none":
        return "", bytes
    raise ValueError(f"compression must be zstd, lz4 or none, got {compression!r}")


class McapFileWriter:
    """Writes one MCAP file to a binary ``stream``: ``add_schema``, ``add_channel``, ``add_message``,
    ``add_metadata``, ``flush``, ``finish``. A chunk ends when it holds more than ``chunk_size``
    bytes (before compression), at ``flush`` and at ``finish``.

    After ``finish``: ``message_counts`` ({channel id: messages}), ``message_start_time``,
    ``message_end_time`` (0 and 0 without messages), as the Statistics record holds them.
    """

    def __init__(self, stream, profile: str, library: str, compression="zstd", chunk_size=1024 * 1024):
        self._out = stream
        self.compression, self._compress = _compressor(compression)
        self.chunk_size = int(chunk_size)
        self._schemas, self._channels = [], []
        self._chunk_indexes, self._metadata_indexes = [], []
        self.message_counts = {}
        self.message_start_time = self.message_end_time = None
        self._new_chunk()
        self._out.write(MAGIC)
        self._write(Header(profile=profile, library=library))

    # -- records ----------------------------------------------------------------------------------
    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._chunk += _record_bytes(schema)
        return schema.id

    def add_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata))
        self._channels.append(channel)
        self.message_counts[channel.id] = 0
        self._chunk += _record_bytes(channel)
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data, publish_time: int, sequence: int = 0):
        """Append a Message record to the chunk in progress (the hot path: no object, one pack)."""
        chunk = self._chunk
        index = self._message_index.get(channel_id)
        if index is None:
            index = self._message_index[channel_id] = bytearray()
        index += _INDEX_PAIR.pack(log_time, len(chunk))
        chunk += MESSAGE_RECORD.pack(Opcode.MESSAGE, _MESSAGE_FIELDS + len(data), channel_id, sequence, log_time,
                                     publish_time)
        chunk += data
        if len(chunk) > self.chunk_size:
            self._end_chunk()

    def add_records(self, payload: bytes, channels: dict, sequences: dict):
        """The messages of an ``M`` frame (:mod:`biped_sim.recording.frames`), numbered as
        :func:`~biped_sim.recording.frames.add_numbered` numbers them: the same records as one
        ``add_message`` each, in one C call a chunk when the compiled twin was built."""
        if append_messages is None:
            add_numbered(self.add_message, payload, channels, sequences)
            return
        offset, end = 0, len(payload)
        while offset < end:
            offset = append_messages(payload, offset, self._chunk, self.chunk_size, self._message_index, channels,
                                     sequences)
            if len(self._chunk) > self.chunk_size:
                self._end_chunk()

    def add_metadata(self, name: str, metadata: dict):
        """A Metadata record, written at once between chunks (the chunk in progress stays open)."""
        offset = self._out.tell()
        length = self._write(Metadata(name=name, metadata=dict(metadata)))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    def flush(self):
        """End the chunk in progress (if it holds a message) and flush the stream."""
        self._end_chunk()
        self._out.flush()

    def finish(self):
        """End the data section and write the summary, the footer and the closing magic."""
        self._end_chunk()
        self._write(DataEnd(data_section_crc=0))      # 0: no CRC of the data section, as mcap's default
        summary_start = self._out.tell()
        summary, offsets = RecordBuilder(), []
        groups = ((Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                  (Opcode.STATISTICS, [self._statistics()]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.ATTACHMENT_INDEX, []), (Opcode.METADATA_INDEX, self._metadata_indexes))
        for opcode, records in groups:
            start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                         group_length=summary.count - start))
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        crc = zlib.crc32(_FOOTER_START.pack(Opcode.FOOTER, 20, summary_start, summary_offset_start),
                         zlib.crc32(data))
        self._out.write(data)
        self._write(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc))
        self._out.write(MAGIC)
        self._out.flush()
        if self.message_start_time is None:
            self.message_start_time = self.message_end_time = 0

    # -- internals -------------------------------------------------------------------------------
    def _write(self, record) -> int:
        data = _record_bytes(record)
        self._out.write(data)
        return len(data)

    def _new_chunk(self):
        self._chunk = bytearray()
        self._message_index = {}      # channel id -> bytearray: (log time, offset in the chunk) as <QQ pairs

    def _end_chunk(self):
        if not self._message_index:
            return
        raw = bytes(self._chunk)
        times = [_log_times(pairs) for pairs in self._message_index.values()]
        start, end = min(map(min, times)), max(map(max, times))
        packed = self._compress(raw)
        chunk_start = self._out.tell()
        chunk_length = self._write(Chunk(compression=self.compression, data=packed, message_start_time=start,
                                         message_end_time=end, uncompressed_crc=zlib.crc32(raw),
                                         uncompressed_size=len(raw)))
        index_start = self._out.tell()
        index_offsets, indexes = {}, bytearray()
        for channel_id, pairs in self._message_index.items():
            index_offsets[channel_id] = index_start + len(indexes)
            indexes += _message_index_bytes(channel_id, pairs)
            self.message_counts[channel_id] = self.message_counts.get(channel_id, 0) + len(pairs) // _INDEX_PAIR.size
        index_length = len(indexes)
        self._out.write(indexes)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_start, chunk_length=chunk_length,
            message_index_offsets=index_offsets, message_index_length=index_length, compression=self.compression,
            compressed_size=len(packed), uncompressed_size=len(raw)))
        self.message_start_time = start if self.message_start_time is None else min(start, self.message_start_time)
        self.message_end_time = end if self.message_end_time is None else max(end, self.message_end_time)
        self._new_chunk()

    def _statistics(self):
        counts = self.message_counts
        return Statistics(
            message_count=sum(counts.values()), schema_count=len(self._schemas), channel_count=len(self._channels),
            attachment_count=0, metadata_count=len(self._metadata_indexes), chunk_count=len(self._chunk_indexes),
            message_start_time=self.message_start_time or 0, message_end_time=self.message_end_time or 0,
            channel_message_counts={cid: n for cid, n in counts.items() if n})


def _message_index_bytes(channel_id: int, pairs) -> bytes:
    """The MessageIndex record of a channel in a chunk from its (log time, offset) pairs already packed
    as ``<QQ`` (``pairs``, bytes-like, as ``add_message`` and the compiled ``append_messages`` keep them):
    the bytes of mcap's ``MessageIndex(channel_id, records).write`` (tested). Why packed as they come:
    a (time, offset) tuple a message, flattened and packed at the end of each chunk, costs the writer process
    more per message, and the writer's work slows a fast run on the other vCPU."""
    return _MESSAGE_INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + len(pairs), channel_id, len(pairs)) + pairs


def _log_times(pairs):
    """The log times of packed ``<QQ`` (log time, offset) pairs (a sequence of ints)."""
    if sys.byteorder == "little":
        return memoryview(pairs).cast("Q")[::2]
    values = array.array("Q", bytes(pairs))
    values.byteswap()
    return values[::2]


def _record_bytes(record) -> bytes:
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()
