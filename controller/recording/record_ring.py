"""The shared-memory ring that carries the record stream (record_stream.py) from the control
cycle to the recording writer process (writer_process.py).

A pipe cost the cycle one system call per record (issue 35: in situ ~20 us of the 30 us a
lockstep cycle spent handing its record over); the ring costs it a copy into memory both
processes map: the cycle packs its record straight into the ring and then publishes the new
end of the stream, one 8-byte store. The writer process wakes every BATCH_PERIOD, takes
everything published, serialises it and publishes how far it has taken, which frees the room.

The memory is an anonymous shared file (memfd) the writer process inherits, so the records
outlive the daemon: when the daemon dies (even by SIGKILL) the writer still takes every record
published before, writes them and ends. A record the daemon was killed in the middle of was
never published and is not read.

Layout: HEADER bytes of header, then `capacity` bytes of stream, wrapping around.
    offset 0   u64  bytes published by the producer since the start (only the producer writes it)
    offset 64  u64  bytes taken by the consumer since the start (only the consumer writes it)
Each counter has its own cache line and is written by one 8-byte copy (struct's native path on
a little-endian machine); it is read until two readings in a row agree, so a reading torn by
a copy done in parts cannot pass for a count. The producer writes a record's bytes, then its counter;
on x86 another core sees stores in that order. On a CPU that may reorder stores the consumer
is still safe in practice: it reads only up to the counter it saw at its previous wake-up
(BATCH_PERIOD earlier), except once the producer has closed the stream or died (a system call
or a process exit lies between the last record and that news).
"""
from __future__ import annotations

import mmap
import os
import struct
import tempfile

HEADER = 128
PUBLISHED_AT, TAKEN_AT = 0, 64
_U64 = struct.Struct("<Q")


def _counter(view: mmap.mmap, at: int) -> int:
    """The other side's counter: two equal readings in a row (a torn one is not repeated)."""
    value = _U64.unpack_from(view, at)[0]
    while (again := _U64.unpack_from(view, at)[0]) != value:
        value = again
    return value


def _shared_fd(size: int) -> int:
    """A file descriptor of `size` bytes of memory a child process can map (memfd on Linux)."""
    if hasattr(os, "memfd_create"):
        fd = os.memfd_create("spacearm-recording")
    else:                                   # elsewhere: an unlinked temporary file
        fd, name = tempfile.mkstemp(prefix="spacearm-recording-")
        os.unlink(name)
    os.ftruncate(fd, size)
    return fd


class RingProducer:
    """The daemon's side. Not thread-safe: the caller holds its own lock."""

    def __init__(self, capacity: int):
        if capacity <= 0:
            raise ValueError(f"recording ring capacity must be > 0 bytes, got {capacity}")
        self.capacity = capacity
        self.fd = _shared_fd(HEADER + capacity)
        self.map = mmap.mmap(self.fd, HEADER + capacity)
        self.map.write(bytes(HEADER + capacity))   # every page touched now, not in a cycle
        self.published = 0
        self._taken = 0          # the consumer's counter as last read

    def room(self, size: int) -> bool:
        """True if `size` more bytes fit (the consumer's counter is read only when the last
        reading says they do not)."""
        if self.published + size - self._taken <= self.capacity:
            return True
        self._taken = _counter(self.map, TAKEN_AT)
        return self.published + size - self._taken <= self.capacity

    def reserve(self, size: int) -> int:
        """The cycle's one call before packing a record of `size` bytes: where in `map` it goes
        whole (> 0), 0 if it fits but wraps around (pack it elsewhere and `copy` it), -1 if it
        does not fit."""
        published = self.published
        if published + size - self._taken > self.capacity:
            self._taken = _counter(self.map, TAKEN_AT)
            if published + size - self._taken > self.capacity:
                return -1
        position = published % self.capacity
        return HEADER + position if position + size <= self.capacity else 0

    def copy(self, record: bytes | bytearray | memoryview) -> None:
        """A record's bytes at the write position, split at the ring's end if need be (after
        `room` or `reserve`; not published yet)."""
        position, size = self.published % self.capacity, len(record)
        first = min(size, self.capacity - position)
        self.map[HEADER + position:HEADER + position + first] = record[:first]
        if first < size:
            self.map[HEADER:HEADER + size - first] = record[first:]

    def publish(self, size: int) -> None:
        """The `size` bytes written at the write position are part of the stream from now on."""
        self.published += size
        _U64.pack_into(self.map, PUBLISHED_AT, self.published)

    def put(self, record: bytes | bytearray) -> bool:
        """Copy and publish a whole record, or False (nothing written) if it does not fit."""
        if not self.room(len(record)):
            return False
        self.copy(record)
        self.publish(len(record))
        return True

    def close(self) -> None:
        """Unmap (the consumer keeps its own mapping)."""
        self.map.close()
        os.close(self.fd)


class RingConsumer:
    """The writer process's side."""

    def __init__(self, fd: int):
        size = os.fstat(fd).st_size
        self.capacity = size - HEADER
        self.map = mmap.mmap(fd, size)
        os.close(fd)
        self.taken = _counter(self.map, TAKEN_AT)

    def published(self) -> int:
        return _counter(self.map, PUBLISHED_AT)

    def take(self, upto: int) -> bytes:
        """A copy of the stream from where the consumer is up to byte `upto` (a published
        count); `release` then frees its room."""
        start = self.taken
        if upto <= start:
            return b""
        position, size = start % self.capacity, upto - start
        first = min(size, self.capacity - position)
        data = self.map[HEADER + position:HEADER + position + first]
        if first < size:
            data += self.map[HEADER:HEADER + size - first]
        self.taken = upto
        return data

    def release(self) -> None:
        """Tell the producer everything taken so far may be overwritten."""
        _U64.pack_into(self.map, TAKEN_AT, self.taken)
