"""The SDO server's transfer state, which canopen's SdoServer does not keep: a simulated node
screens each request with it before the library answers.

CiA 301 rules this adds to the library's server:
- a client's abort (ccs 4) ends the transfer in progress, and nothing is answered;
- a segment request (upload or download) with no transfer of that kind in progress is
  answered with abort 0x05040001 (command specifier not valid), never with data;
- a block upload whose protocol switch threshold forbids a switch (pst = 0), or whose object
  is larger than the threshold, is refused with 0x05040001 (the server has no block transfer);
  otherwise the server may switch to a normal upload (CiA 301 7.2.4.3.12);
- a transfer the client leaves unfinished for ``timeout`` s is aborted by the server with
  0x05040000 (SDO protocol timed out).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

from spacearm.base.canopen.codes import ABORT_COMMAND, ABORT_TIMEOUT

SERVER_TIMEOUT = 1.0   # s; a client's own SDO timeout is typically 0.5 s

CCS_SEGMENT_DOWNLOAD, CCS_INIT_DOWNLOAD, CCS_INIT_UPLOAD = 0x00, 0x20, 0x40
CCS_SEGMENT_UPLOAD, CCS_ABORT, CCS_BLOCK_DOWNLOAD, CCS_BLOCK_UPLOAD = 0x60, 0x80, 0xC0, 0xA0


@dataclass
class SdoSession:
    active: str | None = None          # "upload" / "download" while a segmented transfer runs
    index: int = 0
    sub: int = 0
    last: float = 0.0                  # monotonic time of the last request of the transfer
    timeout: float = SERVER_TIMEOUT

    def screen(self, data: bytes, now: float, object_size) -> tuple[bool, int | None]:
        """Before the library sees a request: (pass it on?, abort code to answer or None)."""
        ccs = data[0] & 0xE0
        if ccs in (CCS_INIT_UPLOAD, CCS_INIT_DOWNLOAD, CCS_BLOCK_UPLOAD, CCS_BLOCK_DOWNLOAD):
            self.index, self.sub = struct.unpack_from("<HB", data, 1)
        if ccs == CCS_ABORT:
            self.active = None
            return False, None
        if ccs == CCS_SEGMENT_UPLOAD and self.active != "upload" \
                or ccs == CCS_SEGMENT_DOWNLOAD and self.active != "download":
            self.active = None
            return False, ABORT_COMMAND
        if ccs == CCS_BLOCK_UPLOAD:
            if data[0] & 0x03:        # end or start of a block upload we never began
                return False, ABORT_COMMAND
            pst = data[5]             # byte 4 block size, byte 5 protocol switch threshold
            size = object_size(self.index, self.sub)
            if pst == 0 or size is None or size > pst:
                return False, ABORT_COMMAND
        self.last = now
        return True, None

    def after(self, data: bytes, segmented_left: bool) -> None:
        """After the library answered: is a segmented transfer now in progress?"""
        ccs = data[0] & 0xE0
        if ccs in (CCS_INIT_UPLOAD, CCS_BLOCK_UPLOAD, CCS_SEGMENT_UPLOAD):
            self.active = "upload" if segmented_left else None
        elif ccs == CCS_INIT_DOWNLOAD:
            self.active = None if data[0] & 0x02 else "download"     # expedited: done
        elif ccs == CCS_SEGMENT_DOWNLOAD:
            self.active = None if data[0] & 0x01 else "download"     # c bit: last segment

    def aborted(self) -> None:
        """The server sent an abort: whatever ran is over."""
        self.active = None

    def expired(self, now: float) -> tuple[int, int, int] | None:
        """(index, sub, abort code) when the running transfer timed out (and ends it)."""
        if self.active is not None and now - self.last > self.timeout:
            self.active = None
            return self.index, self.sub, ABORT_TIMEOUT
        return None
