"""Object-dictionary indices, named once for the whole stack.

Both the controller-side drivers and the simulated firmware import their indices from
here; the EDS files in configs/eds/ are generated from the same names
(firmware_sim/eds_builder.py), so an index is written down exactly once.

(index, subindex) pairs are plain tuples; ``OD_NAMES`` gives the EDS parameter names.
"""
from __future__ import annotations

from enum import IntEnum

# --- CiA 301 communication profile area -------------------------------------------
DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
PREDEFINED_ERROR_FIELD = 0x1003
COB_ID_SYNC = 0x1005
COMM_CYCLE_PERIOD = 0x1006
DEVICE_NAME = 0x1008
HW_VERSION = 0x1009
SW_VERSION = 0x100A
GUARD_TIME = 0x100C            # UNSIGNED16 ms (node guarding)
LIFE_TIME_FACTOR = 0x100D      # UNSIGNED8
STORE_PARAMETERS = 0x1010     # sub 1: save all ("save" signature), where the device can store
COB_ID_EMCY = 0x1014
CONSUMER_HEARTBEAT = 0x1016
PRODUCER_HEARTBEAT = 0x1017
IDENTITY = 0x1018
VERIFY_CONFIGURATION = 0x1020  # sub 1 configuration date, sub 2 configuration time (CiA 302-2)
STORE_SIGNATURE = 0x65766173   # "save" as UNSIGNED32, written to 1010h sub 1

RPDO_COMM = 0x1400  # + n (0..511)
RPDO_MAP = 0x1600
TPDO_COMM = 0x1800
TPDO_MAP = 0x1A00
N_PDOS = 4           # PDOs 1..4 of each direction have pre-defined COB-IDs; up to 512 exist
MAX_MAPPED = 8       # mapping entries per PDO

# PDO communication parameter sub-indices
PDO_COB_ID = 1
PDO_TRANSMISSION_TYPE = 2
PDO_INHIBIT_TIME = 3
PDO_EVENT_TIMER = 5
PDO_SYNC_START = 6
PDO_COB_ID_INVALID = 0x8000_0000   # bit 31 of the COB-ID: PDO does not exist / disabled (= canopen_codes.COB_ID_INVALID)
TRANSMISSION_SYNC = 1              # transmission type 1: on every SYNC

# Pre-defined connection set (CiA 301 7.3.5): the numbers live in base/canopen/codes.py
from spacearm.base.canopen.codes import (EMCY_BASE, HEARTBEAT_BASE, NMT_COB_ID, RPDO_BASE,  # noqa: E402,F401
                                   SDO_RX_BASE, SDO_TX_BASE, SYNC_COB_ID_DEFAULT, TPDO_BASE)

# Error register bits (1001h)
ERR_REG_GENERIC = 0x01
ERR_REG_CURRENT = 0x02
ERR_REG_VOLTAGE = 0x04
ERR_REG_TEMPERATURE = 0x08
ERR_REG_COMMUNICATION = 0x10
ERR_REG_PROFILE = 0x20
ERR_REG_MANUFACTURER = 0x80

# EMCY error codes used by the devices (base/canopen/codes.py)
from spacearm.base.canopen.codes import (EMCY_EE_JAM, EMCY_EE_SCREW_TORQUE, EMCY_FOLLOWING_ERROR,  # noqa: E402,F401
                                   EMCY_FT_OVERLOAD, EMCY_GENERIC, EMCY_HEARTBEAT_ERROR, EMCY_NO_ERROR,
                                   EMCY_OVER_TEMPERATURE_DEVICE, EMCY_OVER_TEMPERATURE_DRIVE, EMCY_PDO_LENGTH,
                                   EMCY_POSITION_LIMIT)

# --- CiA 402 drive profile (joint drives) -----------------------------------------
ERROR_CODE = 0x603F
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
QUICK_STOP_OPTION = 0x605A
FAULT_REACTION_OPTION = 0x605E
MODES_OF_OPERATION = 0x6060
MODES_OF_OPERATION_DISPLAY = 0x6061
POSITION_DEMAND = 0x6062
POSITION_ACTUAL = 0x6064
FOLLOWING_ERROR_WINDOW = 0x6065
FOLLOWING_ERROR_TIMEOUT = 0x6066
POSITION_WINDOW = 0x6067
VELOCITY_ACTUAL = 0x606C
TARGET_TORQUE = 0x6071
MAX_TORQUE = 0x6072
MOTOR_RATED_TORQUE = 0x6076
TORQUE_ACTUAL = 0x6077
TARGET_POSITION = 0x607A
SOFTWARE_POSITION_LIMIT = 0x607D   # sub 1 min, sub 2 max
MAX_PROFILE_VELOCITY = 0x607F
PROFILE_VELOCITY = 0x6081
PROFILE_ACCELERATION = 0x6083
PROFILE_DECELERATION = 0x6084
QUICK_STOP_DECELERATION = 0x6085
POSITION_ENCODER_RESOLUTION = 0x608F  # sub 1 encoder increments, sub 2 motor revolutions
GEAR_RATIO = 0x6091                   # sub 1 motor revolutions, sub 2 shaft revolutions
FEED_CONSTANT = 0x6092                # sub 1 feed (um here, see axis_scale.py), sub 2 shaft revolutions
VELOCITY_OFFSET = 0x60B1
TORQUE_OFFSET = 0x60B2
INTERPOLATION_TIME_PERIOD = 0x60C2    # sub 1 value, sub 2 index (10^index s)
FOLLOWING_ERROR_ACTUAL = 0x60F4
SUPPORTED_DRIVE_MODES = 0x6502

# manufacturer-specific joint objects
DRIVE_TEMPERATURE = 0x2000   # INTEGER16, 0.1 degC
BRAKE_STATUS = 0x2001        # UNSIGNED8, 1 = brake engaged

MODE_PROFILE_POSITION = 1
MODE_CSP = 8

# --- End-effector controller (manufacturer specific, 2100h..) ----------------------
EE_COMMAND = 0x2100          # UNSIGNED8, see EeCommand
EE_STATE = 0x2101            # UNSIGNED8, see EeState
EE_SCREW_TORQUE = 0x2102     # INTEGER16, mN m
EE_SCREW_TURNS = 0x2103      # INTEGER32, milli-turns
EE_GRIP_POSITION = 0x2104    # UNSIGNED16, per mille of stroke (0 open, 1000 closed)
EE_FAULT_CODE = 0x2105       # UNSIGNED16, last EMCY code (0 = none)
EE_SCREW_TORQUE_LIMIT = 0x2110   # UNSIGNED16, mN m: lock torque
EE_LOCK_TURNS = 0x2111           # UNSIGNED32, milli-turns to full lock

# --- Six-axis force/torque sensor (manufacturer specific, 2200h..) -----------------
FT_VALUES = 0x2200           # ARRAY of INTEGER16, sub 1..6 = Fx Fy Fz Tx Ty Tz
FT_FORCE_COUNTS_PER_N = 0x2201
FT_TORQUE_COUNTS_PER_NM = 0x2202
FT_STATUS = 0x2203           # UNSIGNED8, bit 0 overload, bit 1 tared
FT_TARE = 0x2204             # UNSIGNED8, write 1: tare (bias = current load), 2: clear bias
FT_OVERLOAD_LIMIT = 0x2205   # sub 1 force N, sub 2 torque N m (UNSIGNED16)

FT_STATUS_OVERLOAD = 0x01
FT_STATUS_TARED = 0x02

# --- Simulation fault-injection unit (test rig node, only in `spacearm sim --control-node ID`)
SIM_TARGET_NODE = 0x2F00       # UNSIGNED8: node ID the following objects act on
SIM_SILENT = 0x2F01            # UNSIGNED8: 1 = node sends nothing and ignores the bus
SIM_HEARTBEAT_STOPPED = 0x2F02 # UNSIGNED8: 1 = heartbeat producer stops
SIM_SDO_ABORT = 0x2F03         # UNSIGNED32: abort every SDO with this code (0 = off)
SIM_DROP_TPDOS = 0x2F04        # UNSIGNED16: drop the next N TPDOs
SIM_CORRUPT_TPDOS = 0x2F05     # UNSIGNED16: truncate the next N TPDOs by one byte
SIM_RAISE_FAULT = 0x2F06       # UNSIGNED16: the device detects a fault with this EMCY code
SIM_STALL = 0x2F07             # UNSIGNED8: 1 = joint mechanism jammed
SIM_TEMPERATURE = 0x2F08       # INTEGER16: drive temperature, 0.1 degC
SIM_POWER_CYCLE = 0x2F09       # UNSIGNED8: write 1 = node reboots
SIM_EE_TARGET_PRESENT = 0x2F0A # UNSIGNED8: an ORU interface is in the end-effector grip
SIM_WRENCH = 0x2F0B            # ARRAY of INTEGER32, sub 1..6: wrench at the F/T sensor, mN / mN m
SIM_IGNORE_SYNC = 0x2F0C       # UNSIGNED8: 1 = node stops sending TPDOs
SIM_FREEZE = 0x2F0D            # UNSIGNED8: 1 = node keeps sending its last TPDO values (frozen sensor)
SIM_CONTROL_NODE_DEFAULT = 126

# NMT
NMT_START = 0x01
NMT_STOP = 0x02
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
NMT_STATE_BOOTUP = 0x00
NMT_STATE_STOPPED = 0x04
NMT_STATE_OPERATIONAL = 0x05
NMT_STATE_PRE_OPERATIONAL = 0x7F
NMT_STATE_NAMES = {0x00: "INITIALISING", 0x04: "STOPPED", 0x05: "OPERATIONAL", 0x7F: "PRE-OPERATIONAL"}

DEVICE_TYPES = ("joint_drive", "end_effector", "ft_sensor")


class EeCommand(IntEnum):
    """End-effector command codes (2100h), shared by the device and the driver."""
    NONE = 0
    CLAMP = 1        # close the grip, then screw until locked
    RELEASE = 2      # unscrew, then open the grip
    STOP = 3
    FAULT_RESET = 4
    # The screw drive turns the ORU's connection bolt, which drives the store's latch (ORU
    # paper Table 1 subtasks 5 and 10); accepted only while clamped and locked on an adapter.
    LATCH_UNLOCK = 5
    LATCH_LOCK = 6


class EeState(IntEnum):
    """End-effector state codes (2101h), shared by the device and the driver."""
    UNKNOWN = 0
    OPEN = 1
    CLOSING = 2
    LOCKING = 3
    LOCKED = 4       # clamped and locked
    UNLOCKING = 5
    OPENING = 6      # releasing
    STOPPED = 7      # stopped part way by command
    FAULT = 8
