"""Fixed reference workloads timed in the benchmark's own run and process, so a cycle's cost
can be quoted in units that do not depend on the machine (issue 35): a ~3x slower machine takes
~3x as long for both, and the ratio stays put.

- the reference loop: `s += i*i` for 2,000,000 i, pure Python (320-420 ms on the slower of
  the project's machines, ~120 ms on the faster);
- the PDO floor: N CAN frames packed and unpacked with precompiled `struct` layouts (a CSP
  RPDO: controlword + target position; a TPDO: statusword + position + velocity) - what one
  lockstep cycle cannot go below in Python for the frames it exchanges.

Each is the median of `repeats` timings, as (wall, process CPU) seconds: the wall figure
compares with a lockstep cycle's wall time (both stretch when the machine is busy), the CPU
figure with its CPU time (neither counts time spent waiting for a core)."""
from __future__ import annotations

import statistics
import struct
import time

REFERENCE_LOOP_N = 2_000_000
_RPDO = struct.Struct("<Hi")     # 6040h controlword, 607Ah target position
_TPDO = struct.Struct("<Hii")    # 6041h statusword, 6064h position, 606Ch velocity


def _medians(work, repeats: int) -> tuple[float, float]:
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        work()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


def reference_loop_seconds(repeats: int = 5) -> tuple[float, float]:
    """(wall, CPU) seconds of the pure-Python reference loop, medians."""
    def loop():
        s = 0
        for i in range(REFERENCE_LOOP_N):
            s += i * i
        return s
    return _medians(loop, repeats)


def pdo_floor_seconds(frames: int, repeats: int = 5) -> tuple[float, float]:
    """(wall, CPU) seconds to pack and unpack `frames` PDO frames, half RPDO and half TPDO
    layouts, medians."""
    rpdo_pack, rpdo_unpack, tpdo_pack, tpdo_unpack = _RPDO.pack, _RPDO.unpack, _TPDO.pack, _TPDO.unpack
    half = max(1, frames // 2)

    def floor():
        for k in range(half):
            rpdo_unpack(rpdo_pack(0x0F, k))
            tpdo_unpack(tpdo_pack(0x1237, k, -k))
    return _medians(floor, repeats)
