"""The CANopen numbers of CiA 301/402, written once: SDO abort codes, EMCY codes, COB-ID
bases and CiA data type codes.

The master (drivers/), the simulated firmware (firmware_sim/) and the EDS writer all import
them from here. Standard library only and no imports from the rest of the repository: this
module belongs to the shared base below drivers/ and firmware_sim/.
"""
from __future__ import annotations

# --- Pre-defined connection set (CiA 301 7.3.5): COB-ID = base + node ID ---------------
NMT_COB_ID = 0x000
SYNC_COB_ID_DEFAULT = 0x080
EMCY_BASE = 0x080
TPDO_BASE = (0x180, 0x280, 0x380, 0x480)
RPDO_BASE = (0x200, 0x300, 0x400, 0x500)
SDO_TX_BASE = 0x580   # server -> client
SDO_RX_BASE = 0x600   # client -> server
HEARTBEAT_BASE = 0x700
COB_ID_INVALID = 0x8000_0000   # bit 31 of a PDO/EMCY COB-ID: not valid (disabled)

# --- CiA 301 data type codes (DataType= in an EDS) --------------------------------------
BOOLEAN = 0x0001
INTEGER8 = 0x0002
INTEGER16 = 0x0003
INTEGER32 = 0x0004
UNSIGNED8 = 0x0005
UNSIGNED16 = 0x0006
UNSIGNED32 = 0x0007
REAL32 = 0x0008
VISIBLE_STRING = 0x0009
OCTET_STRING = 0x000A
DOMAIN = 0x000F
REAL64 = 0x0011
INTEGER64 = 0x0015
UNSIGNED64 = 0x001B

# size in bits of the fixed-size types (what a PDO mapping entry must state)
DATATYPE_BITS = {BOOLEAN: 1, INTEGER8: 8, INTEGER16: 16, INTEGER32: 32, UNSIGNED8: 8, UNSIGNED16: 16,
                 UNSIGNED32: 32, REAL32: 32, REAL64: 64, INTEGER64: 64, UNSIGNED64: 64}

# --- Object types (ObjectType= in an EDS) ------------------------------------------------
OBJECT_VAR = 0x7
OBJECT_ARRAY = 0x8
OBJECT_RECORD = 0x9

# --- SDO abort codes (CiA 301 table 22) --------------------------------------------------
ABORT_TOGGLE = 0x0503_0000
ABORT_TIMEOUT = 0x0504_0000
ABORT_COMMAND = 0x0504_0001
ABORT_BLOCK_SIZE = 0x0504_0002
ABORT_SEQUENCE = 0x0504_0003
ABORT_CRC = 0x0504_0004
ABORT_OUT_OF_MEMORY = 0x0504_0005
ABORT_UNSUPPORTED_ACCESS = 0x0601_0000
ABORT_WRITE_ONLY = 0x0601_0001
ABORT_READ_ONLY = 0x0601_0002
ABORT_NO_OBJECT = 0x0602_0000
ABORT_NOT_MAPPABLE = 0x0604_0041
ABORT_PDO_LENGTH = 0x0604_0042
ABORT_PARAM_INCOMPATIBLE = 0x0604_0043
ABORT_INTERNAL_INCOMPATIBLE = 0x0604_0047
ABORT_HARDWARE = 0x0606_0000
ABORT_LENGTH = 0x0607_0010
ABORT_LENGTH_HIGH = 0x0607_0012
ABORT_LENGTH_LOW = 0x0607_0013
ABORT_NO_SUBINDEX = 0x0609_0011
ABORT_VALUE_INVALID = 0x0609_0030
ABORT_VALUE_HIGH = 0x0609_0031
ABORT_VALUE_LOW = 0x0609_0032
ABORT_MAX_LESS_MIN = 0x0609_0036
ABORT_GENERAL = 0x0800_0000
ABORT_STORE = 0x0800_0020
ABORT_LOCAL_CONTROL = 0x0800_0021
ABORT_DEVICE_STATE = 0x0800_0022
ABORT_NO_DICTIONARY = 0x0800_0023

# wording as the canopen library's SdoAbortedError.CODES (messages read the same either way)
ABORT_TEXT = {
    ABORT_TOGGLE: "SDO toggle bit error",
    ABORT_TIMEOUT: "Timeout of transfer communication detected",
    ABORT_COMMAND: "Unknown SDO command specified",
    ABORT_BLOCK_SIZE: "Invalid block size",
    ABORT_SEQUENCE: "Invalid sequence number",
    ABORT_CRC: "CRC error",
    ABORT_OUT_OF_MEMORY: "Out of memory",
    ABORT_UNSUPPORTED_ACCESS: "Unsupported access to an object",
    ABORT_WRITE_ONLY: "Attempt to read a write only object",
    ABORT_READ_ONLY: "Attempt to write a read only object",
    ABORT_NO_OBJECT: "Object does not exist",
    ABORT_NOT_MAPPABLE: "Object cannot be mapped to the PDO",
    ABORT_PDO_LENGTH: "PDO length exceeded",
    ABORT_PARAM_INCOMPATIBLE: "General parameter incompatibility reason",
    ABORT_INTERNAL_INCOMPATIBLE: "General internal incompatibility in the device",
    ABORT_HARDWARE: "Access failed due to a hardware error",
    ABORT_LENGTH: "Data type and length code do not match",
    ABORT_LENGTH_HIGH: "Data type does not match, length of service parameter too high",
    ABORT_LENGTH_LOW: "Data type does not match, length of service parameter too low",
    ABORT_NO_SUBINDEX: "Subindex does not exist",
    ABORT_VALUE_INVALID: "Value range of parameter exceeded",
    ABORT_VALUE_HIGH: "Value of parameter written too high",
    ABORT_VALUE_LOW: "Value of parameter written too low",
    ABORT_MAX_LESS_MIN: "Maximum value is less than minimum value",
    ABORT_GENERAL: "General error",
    ABORT_STORE: "Data cannot be transferred or stored to the application",
    ABORT_LOCAL_CONTROL: "Data can not be transferred or stored to the application because of local control",
    ABORT_DEVICE_STATE: "Data can not be transferred or stored to the application because of the present "
                        "device state",
    ABORT_NO_DICTIONARY: "Object dictionary dynamic generation fails or no object dictionary is present",
}

# aborts that mean "the device has no such object" (an optional object that is absent)
ABORTS_ABSENT = frozenset({ABORT_NO_OBJECT, ABORT_NO_SUBINDEX})


def abort_text(code: int) -> str:
    return ABORT_TEXT.get(code, "unknown abort code")


# --- EMCY error codes (CiA 301 table 21, CiA 402, and ours) ------------------------------
EMCY_NO_ERROR = 0x0000
EMCY_GENERIC = 0x1000
EMCY_OVER_TEMPERATURE_DEVICE = 0x4210
EMCY_OVER_TEMPERATURE_DRIVE = 0x4310
EMCY_HEARTBEAT_ERROR = 0x8130
EMCY_PDO_LENGTH = 0x8210
EMCY_FOLLOWING_ERROR = 0x8611
EMCY_POSITION_LIMIT = 0x8612
EMCY_EE_JAM = 0xFF01            # manufacturer specific: end-effector mechanism jammed
EMCY_EE_SCREW_TORQUE = 0xFF02   # manufacturer specific: screw torque limit before lock
EMCY_FT_OVERLOAD = 0xFF10       # manufacturer specific: force/torque overload

EMCY_TEXT = {
    EMCY_NO_ERROR: "error reset / no error",
    EMCY_GENERIC: "generic error",
    0x2000: "current",
    0x3000: "voltage",
    0x4000: "temperature",
    EMCY_OVER_TEMPERATURE_DEVICE: "device over temperature",
    EMCY_OVER_TEMPERATURE_DRIVE: "drive over temperature",
    0x8100: "communication",
    EMCY_HEARTBEAT_ERROR: "life guard / heartbeat error",
    EMCY_PDO_LENGTH: "PDO not processed due to length error",
    EMCY_FOLLOWING_ERROR: "following error",
    EMCY_POSITION_LIMIT: "position limit",
    EMCY_EE_JAM: "end-effector mechanism jammed",
    EMCY_EE_SCREW_TORQUE: "end-effector lock torque not reached",
    EMCY_FT_OVERLOAD: "force/torque sensor overload",
}


def emcy_text(code: int) -> str:
    if code in EMCY_TEXT:
        return EMCY_TEXT[code]
    return EMCY_TEXT.get(code & 0xFF00, EMCY_TEXT.get(code & 0xF000, f"error 0x{code:04X}"))
