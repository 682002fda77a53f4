"""Exceptions and events of the controller-side drivers. Messages name the node."""
from __future__ import annotations

from dataclasses import dataclass, field
import time

from canopen.sdo.exceptions import SdoAbortedError


class DriverError(Exception):
    """Base of every error the drivers raise."""


class BootError(DriverError):
    """Network bring-up failed (node missing, wrong device, configuration refused)."""


class SdoError(DriverError):
    """An SDO transfer was aborted by the node (``code`` is the CiA 301 abort code)."""

    def __init__(self, node_label: str, action: str, index: int, subindex: int, code: int):
        self.node_label, self.index, self.subindex, self.code = node_label, index, subindex, code
        self.meaning = SdoAbortedError.CODES.get(code, "unknown abort code")
        super().__init__(f"{node_label}: SDO {action} 0x{index:04X}:{subindex:02X} aborted with "
                         f"0x{code:08X} ({self.meaning})")


class SdoTimeoutError(DriverError):
    """The node did not answer an SDO request."""


class FaultResetError(DriverError):
    """A fault reset did not clear the fault."""


# EMCY error codes -> text (CiA 301 / 402 plus ours)
EMCY_TEXT = {
    0x0000: "error reset / no error",
    0x1000: "generic error",
    0x4210: "device over temperature",
    0x4310: "drive over temperature",
    0x8130: "life guard / heartbeat error",
    0x8210: "PDO not processed due to length error",
    0x8611: "following error",
    0x8612: "position limit",
    0xFF01: "end-effector mechanism jammed",
    0xFF02: "end-effector lock torque not reached",
    0xFF10: "force/torque sensor overload",
}


def emcy_text(code: int) -> str:
    if code in EMCY_TEXT:
        return EMCY_TEXT[code]
    return EMCY_TEXT.get(code & 0xFF00, f"error 0x{code:04X}")


@dataclass
class NetworkEvent:
    """Something the controller must act on. kind is one of:
    heartbeat_lost, heartbeat_restored, bootup (unexpected reboot), nmt_state, emcy,
    emcy_reset, fault_reset_failed, fault_cleared, tpdo_timeout."""
    kind: str
    node: str
    node_id: int
    message: str
    code: int = 0
    time: float = field(default_factory=time.monotonic)

    def __str__(self) -> str:
        return f"[{self.kind}] {self.message}"
