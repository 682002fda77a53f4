"""Frames and their transport from the camera (simulator or driver) to the controller.

`FrameSource.latest()` is all the controller needs. `ShmFrameRing` is a real inter-process
transport: a multiprocessing.shared_memory ring of N slots, each guarded by a seqlock
(begin/end sequence numbers written around the pixel copy), so a reader in another process
never returns a torn frame and never blocks the writer.

The controller also sets the camera's trigger mode through the source (`set_trigger`, the
ring's last header word; GenICam's TriggerMode/AcquisitionStart in a real camera): free run
(frames at the camera's own rate in wall time, real-time runs) or lockstep (one exposure per
frame period of *plant* time, only while the controller acquires). In lockstep the camera
announces each exposure's SYNC number when it takes it (`announce_exposure`, before the nodes
answer that SYNC) and the controller waits until that frame is published (`published_sync`):
a lockstep run then sees the same frames whatever the machine's load. Another reader (the
camera calibration, `spacearm calibrate camera`) asks an idle lockstep camera for one exposure
at or after a SYNC with `request_exposure`.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from enum import IntEnum
from multiprocessing import resource_tracker, shared_memory
from typing import Protocol

import numpy as np

MAGIC = 0x5341_4D43_414D_0003          # "SAMCAM" v3
HEADER_WORDS = 10                       # magic, width, height, slots, slot_bytes, latest_seq, closed, trigger,
TRIGGER_WORD = 7                        # exposed (SYNC of the newest exposure taken), requested (see
EXPOSED_WORD = 8                        # request_exposure)
REQUEST_WORD = 9
SLOT_META = 6 * 8 + 16 * 8              # begin, end, timestamp, flags, sync, spare, truth (16 x f64)


@dataclass(frozen=True)
class Frame:
    timestamp: float                     # s, time of exposure (the writer's clock: plant time)
    seq: int                             # 1, 2, ... per camera
    image: np.ndarray                    # (H, W) uint8
    true_camera_T_marker: np.ndarray | None = None   # simulator ground truth, tests only
    sync: int = 0                        # number of the SYNC the exposure belongs to (the
                                         # controller's Measurement.sync_counter of that cycle)


class CameraTrigger(IntEnum):
    """Who decides when the camera exposes (set by the frames' consumer, read by the camera)."""
    FREE_RUN = 0            # the camera's own rate in wall time (real-time runs)
    LOCKSTEP_IDLE = 1       # lockstep, acquisition stopped: no exposures (nothing to render)
    LOCKSTEP = 2            # lockstep, acquiring: an exposure every frame period of plant time


class FrameSource(Protocol):
    def latest(self) -> Frame | None:
        """Newest complete frame, or None before the first one."""
        ...


_CREATED_HERE: set[str] = set()     # rings this process owns (their tracker entry must stay)


class ShmFrameRing:
    """Single writer, any number of readers, across processes. Create with `create()` in the
    camera process, `attach(name)` in the controller."""

    def __init__(self, shm: shared_memory.SharedMemory, owner: bool):
        self._shm = shm
        self._owner = owner
        self._header = np.ndarray((HEADER_WORDS,), np.uint64, shm.buf, 0)
        if int(self._header[0]) != MAGIC:
            raise ValueError(f"shared memory {shm.name!r} is not a frame ring")
        self.width, self.height = int(self._header[1]), int(self._header[2])
        self.slots, self.slot_bytes = int(self._header[3]), int(self._header[4])
        self._seq = int(self._header[5])

    # ------------------------------------------------------------------ lifecycle
    @classmethod
    def create(cls, width: int, height: int, slots: int = 4, name: str | None = None) -> "ShmFrameRing":
        slot_bytes = (SLOT_META + width * height + 63) // 64 * 64
        size = HEADER_WORDS * 8 + slots * slot_bytes
        shm = shared_memory.SharedMemory(name=name, create=True, size=size)
        header = np.ndarray((HEADER_WORDS,), np.uint64, shm.buf, 0)
        header[:] = 0
        header[1:5] = (width, height, slots, slot_bytes)
        header[0] = MAGIC
        _CREATED_HERE.add(shm.name)
        return cls(shm, owner=True)

    @classmethod
    def attach(cls, name: str, timeout: float = 5.0, shared_tracker: bool = False) -> "ShmFrameRing":
        """shared_tracker: this process shares the creator's resource tracker (a child spawned by
        multiprocessing), whose entry must stay."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                shm = shared_memory.SharedMemory(name=name, create=False)
            except FileNotFoundError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.01)
                continue
            # Python < 3.13 registers an attached segment with this process's resource
            # tracker, which unlinks it at exit: the owner's ring would vanish for every
            # later reader (and the owner's own unlink would fail).
            if sys.version_info < (3, 13) and shm.name not in _CREATED_HERE and not shared_tracker:
                resource_tracker.unregister(shm._name, "shared_memory")
            return cls(shm, owner=False)

    @property
    def name(self) -> str:
        return self._shm.name

    def close(self) -> None:
        self._header = None             # drop views before closing the mapping
        self._shm.close()
        if self._owner:
            self._shm.unlink()

    def __enter__(self) -> "ShmFrameRing":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ slots
    def _slot(self, index: int):
        base = HEADER_WORDS * 8 + index * self.slot_bytes
        meta = np.ndarray((6,), np.uint64, self._shm.buf, base)
        stamp = np.ndarray((1,), np.float64, self._shm.buf, base + 16)
        truth = np.ndarray((16,), np.float64, self._shm.buf, base + 48)
        image = np.ndarray((self.height, self.width), np.uint8, self._shm.buf, base + SLOT_META)
        return meta, stamp, truth, image

    def set_trigger(self, mode: CameraTrigger) -> None:
        self._header[TRIGGER_WORD] = int(mode)

    def announce_exposure(self, sync: int) -> None:
        self._header[EXPOSED_WORD] = sync

    def exposure_sync(self) -> int:
        """SYNC number of the newest exposure taken (0: none)."""
        return int(self._header[EXPOSED_WORD])

    def request_exposure(self, sync: int) -> None:
        """Ask for an exposure at or after SYNC `sync` even while the lockstep camera is idle."""
        self._header[REQUEST_WORD] = max(int(self._header[REQUEST_WORD]), sync)

    def requested_exposure(self) -> int:
        return int(self._header[REQUEST_WORD])

    def published_sync(self) -> int:
        """SYNC number of the newest published frame (0: none); no pixel copy."""
        seq = int(self._header[5])
        return int(self._slot(seq % self.slots)[0][4]) if seq else 0

    def trigger(self) -> CameraTrigger:
        value = int(self._header[TRIGGER_WORD])
        return CameraTrigger(value) if value in CameraTrigger._value2member_map_ else CameraTrigger.FREE_RUN

    def publish(self, image: np.ndarray, timestamp: float, truth: np.ndarray | None = None,
                sync: int = 0) -> int:
        """Write a frame into the next slot; returns its sequence number."""
        if image.shape != (self.height, self.width) or image.dtype != np.uint8:
            raise ValueError(f"frame must be uint8 {self.height}x{self.width}, got {image.dtype} {image.shape}")
        seq = int(self._header[5]) + 1
        meta, stamp, tr, img = self._slot(seq % self.slots)
        meta[0] = seq                    # begin: slot is being written
        stamp[0] = timestamp
        meta[3] = 1 if truth is not None else 0
        meta[4] = sync
        if truth is not None:
            tr[:] = np.asarray(truth, float).ravel()
        img[:] = image
        meta[1] = seq                    # end: slot complete
        self._header[5] = seq
        return seq

    def latest(self) -> Frame | None:
        for _ in range(self.slots + 2):
            seq = int(self._header[5])
            if seq == 0:
                return None
            meta, stamp, tr, img = self._slot(seq % self.slots)
            if int(meta[1]) != seq:
                continue
            image, t, sync = img.copy(), float(stamp[0]), int(meta[4])
            truth = tr.reshape(4, 4).copy() if int(meta[3]) else None
            if int(meta[0]) == seq and int(meta[1]) == seq:     # not overwritten while copying
                return Frame(t, seq, image, truth, sync)
        return None


class LocalFrameSource:
    """In-process source (single-process runs and tests): holds the last frame pushed."""

    def __init__(self) -> None:
        self._frame: Frame | None = None
        self._trigger = CameraTrigger.FREE_RUN
        self._exposed = 0
        self._requested = 0

    def announce_exposure(self, sync: int) -> None:
        self._exposed = sync

    def exposure_sync(self) -> int:
        return self._exposed

    def request_exposure(self, sync: int) -> None:
        self._requested = max(self._requested, sync)

    def requested_exposure(self) -> int:
        return self._requested

    def published_sync(self) -> int:
        return self._frame.sync if self._frame is not None else 0

    def set_trigger(self, mode: CameraTrigger) -> None:
        self._trigger = CameraTrigger(mode)

    def trigger(self) -> CameraTrigger:
        return self._trigger

    def push(self, frame: Frame) -> None:
        self._frame = frame

    def publish(self, image: np.ndarray, timestamp: float, truth: np.ndarray | None = None,
                sync: int = 0) -> int:
        """Same signature as ShmFrameRing.publish, so the camera writes to either."""
        seq = (self._frame.seq if self._frame is not None else 0) + 1
        self._frame = Frame(timestamp, seq, image, truth, sync)
        return seq

    def latest(self) -> Frame | None:
        return self._frame
