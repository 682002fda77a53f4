"""What a stop did to a joint, judged from recorded positions only (issue 28's bounds).

The speed is the difference of consecutive measured positions over their cycle times, never
the drive's reported velocity or anything the controller commanded: a recording shows what
the joint physically did. Speeds are differences over at least
20 ms (one 50 Hz cycle, five 4 ms cycles), so a resolver step is a few per cent of the limit.
Bounds for a stop from speed v with deceleration limit a at cycle period T: peak speed after
the stop at most min(v, limit) + 5 % of the limit (quantisation),
deceleration monotonic, distance within (v^2 / 2a + v T) + 10 %, time to rest within v / a + 2 T,
and no travel back against the pre-stop direction beyond the standstill window (REST_TOLERANCE).
A position servo settles with a small overshoot (the test bed's simulated drives: 0.11-0.17 mrad,
one to 1.4 resolver steps, read from the plant at 4 and 20 ms); through the resolver that can
read as two steps back within one 20 ms window, so travel back is judged over two windows and
as a distance, as the deceleration's monotony is.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SPEED_TOLERANCE = 0.05     # of the pre-stop speed or limit: encoder quantisation in a difference
DISTANCE_TOLERANCE = 0.10
REST_TOLERANCE = 2.5e-4    # rad: a joint that stays within two resolver steps of its final position is at rest


@dataclass(frozen=True)
class StopFigures:
    joint: int
    v_stop: float            # rad/s, |dq| of the last cycle before the stop
    peak: float              # rad/s, largest |dq| from the stop on
    limit: float             # rad/s
    distance: float          # rad travelled from the stop to rest
    distance_bound: float
    time_to_rest: float      # s (inf: never at rest in the recording)
    time_bound: float
    worst_rise: float        # rad/s: the largest cycle-to-cycle increase of |dq| after the stop
    reversed: float          # rad/s: the largest speed against the pre-stop direction (two windows)
    back_travel: float = 0.0  # rad: the furthest the joint went back from the furthest point it reached

    def problems(self, speed_tolerance: float = SPEED_TOLERANCE) -> list[str]:
        """Each bound the stop broke, in words; empty when it stayed inside all of them."""
        out = []
        quantum = speed_tolerance * self.limit        # what a resolver step does to a difference
        allowed = min(self.v_stop, self.limit) + quantum
        if self.peak > allowed:
            out.append(f"joint {self.joint + 1}: peak {self.peak:.4f} rad/s after the stop above "
                       f"{allowed:.4f} (pre-stop {self.v_stop:.4f}, limit {self.limit:.4f})")
        if self.worst_rise > quantum:
            out.append(f"joint {self.joint + 1}: speed rose by {self.worst_rise:.4f} rad/s in one cycle while stopping")
        if self.reversed > quantum:
            out.append(f"joint {self.joint + 1}: moved back at {self.reversed:.4f} rad/s")
        if self.back_travel > REST_TOLERANCE:
            out.append(f"joint {self.joint + 1}: moved back {1e3 * self.back_travel:.2f} mrad after the stop "
                       f"(standstill window {1e3 * REST_TOLERANCE:.2f} mrad)")
        if self.distance > self.distance_bound:
            out.append(f"joint {self.joint + 1}: stopping distance {1e3 * self.distance:.1f} mrad above "
                       f"{1e3 * self.distance_bound:.1f} mrad")
        if self.time_to_rest > self.time_bound:
            out.append(f"joint {self.joint + 1}: at rest after {self.time_to_rest:.3f} s, bound {self.time_bound:.3f} s")
        return out

    def row(self) -> dict:
        return {"joint": self.joint + 1, "v_stop": self.v_stop, "peak/limit": self.peak / self.limit,
                "distance": self.distance, "distance_bound": self.distance_bound,
                "time": self.time_to_rest, "time_bound": self.time_bound}


def recorded_stop(cycles: list[dict], events: list[dict], period: float,
                  joint_nodes: set[str] | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(plant time, measured q, plant time of the first protective stop) from a recording's
    /cycle and /events messages. Time is the SYNC count times the period: the drives advance
    one period per SYNC, so a cycle the controller ran late (its clock skipped periods) is
    still one period of motion, and dividing by the controller's clock would halve its speed.
    Cycles whose joint drives' process data did not all arrive ("missing"; any node's unless
    `joint_nodes` names the drives) are left out: their positions are the last received, not
    where the joints were (a starved simulator's stale positions read as a joint at rest, then
    one at three times its speed)."""
    cycles = [c for c in cycles
              if not (joint_nodes is None and c.get("missing") or joint_nodes and joint_nodes & set(c.get("missing", ())))]
    sync = np.array([c["sync"] for c in cycles], float)
    t_plant = (sync - sync[0]) * period
    stop = next(e for e in events if e["kind"] == "protective_stop")
    k = int(np.searchsorted(np.array([c["t"] for c in cycles]), stop["t"] - 1e-9))
    return t_plant, np.array([c["q"] for c in cycles]), float(t_plant[k])


def stop_figures(t: np.ndarray, q: np.ndarray, t_stop: float, v_limit: np.ndarray, a_limit: np.ndarray,
                 period: float, joints: list[int] | None = None, one_path: bool = False) -> list[StopFigures]:
    """Figures per joint (all, or `joints`) for a stop at controller time `t_stop`: t (n,) and
    q (n, dof) are the recording's cycle times and measured positions. `one_path`: the joints
    stopped together on one path, each taking the time the slowest to stop needs (v/a of the
    joint with the largest), so each joint's bound uses the deceleration that time gives it."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    k = int(np.searchsorted(t, t_stop - 1e-9))
    if k < 0.02 / period or k >= len(t) - 0.04 / period:
        raise ValueError(f"stop at {t_stop:.3f} s is not inside the recording ({t[0]:.3f}..{t[-1]:.3f} s)")
    span = max(1, int(round(0.02 / period)))
    dq = (q[span:] - q[:-span]) / (t[span:] - t[:-span])[:, None]    # dq[i]: t[i]..t[i+span]
    a_limit = np.asarray(a_limit, float)
    if one_path:
        v_all = np.abs(dq[k - span])
        stop_time = float(np.max(v_all / a_limit))
        if stop_time > 0.0:
            a_limit = np.minimum(a_limit, np.maximum(v_all, 1e-9) / stop_time)
    out = []
    # the pre-stop speed: the last window's, or the mean of the last 100 ms if larger (a
    # resolver step in the last window alone reads a cruising joint 3.5 % slow)
    long = 5 * span if k >= 5 * span else span
    v_mean = np.abs(q[k] - q[k - long]) / (t[k] - t[k - long])
    # monotonic: judged on two-window differences, where one resolver step is half as large
    smooth = (q[2 * span:] - q[:-2 * span]) / (t[2 * span:] - t[:-2 * span])[:, None]
    for j in (range(q.shape[1]) if joints is None else joints):
        v = dq[:, j]
        v_stop = max(abs(v[k - span]), float(v_mean[j]))
        direction = np.sign(v[k - span]) or 1.0
        after = v[k:]
        speed = np.abs(after)
        rest = _rest_index(q[k:, j])
        distance = abs(q[k + rest, j] - q[k, j]) if rest is not None else abs(q[-1, j] - q[k, j])
        along = smooth[k:, j] * direction
        travelled = q[k:, j] * direction
        out.append(StopFigures(
            joint=j, v_stop=float(v_stop), peak=float(speed.max()), limit=float(v_limit[j]),
            distance=float(distance),
            distance_bound=(1.0 + DISTANCE_TOLERANCE) * (v_stop ** 2 / (2.0 * a_limit[j]) + v_stop * period),
            time_to_rest=float(t[k + rest] - t[k]) if rest is not None else float("inf"),
            time_bound=float(v_stop / a_limit[j] + 2.0 * period),
            worst_rise=float(max(0.0, np.max(np.diff(np.concatenate([[v_stop], np.abs(smooth[k:, j])]))))),
            reversed=float(max(0.0, -along.min())),
            back_travel=float(np.max(np.maximum.accumulate(travelled) - travelled))))
    return out


def _rest_index(q: np.ndarray) -> int | None:
    """First index from which q stays within REST_TOLERANCE of its last value (None if it moves
    until the end of the recording, judged by the last few samples)."""
    if len(q) < 3 or abs(q[-1] - q[-3]) > REST_TOLERANCE:
        return None
    away = np.flatnonzero(np.abs(q - q[-1]) > REST_TOLERANCE)
    return int(away[-1] + 1) if away.size else 0
