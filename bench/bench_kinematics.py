"""Kinematics benchmark: prints a table of measured figures against targets.

    .venv/bin/python bench/bench_kinematics.py [--ik-poses 2000] [--seed 1]

Figures per arm: single-call FK + Jacobian latency (median over many calls), batched FK
throughput on 10,000 configurations (median of repeats), and IK from a random nearby seed
(q_true + 0.1-0.3 rad per joint) on random reachable poses: success rate, worst final error,
median time per solve.
"""
from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.base.kinematics import (KinematicData, fk_batch, fk_jacobian, load_model,  # noqa: E402
                                   pose_errors_batch, solve_ik)

ARMS = ("oru_testbed_6dof", "space_robot_6dof_laser", "ssrms_7dof", "ur10", "panda")   # ur10, panda: imported from URDF
TARGET_FKJ_US = 50.0
TARGET_BATCH_CPS = 1e6
TARGET_IK_RATE = 0.999
TARGET_IK_ERR = 1e-6
TARGET_IK_MS = 1.0


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def bench_fkj(model, data, rng, calls: int = 20000) -> float:
    """Median microseconds per fk_jacobian call (each call timed on its own)."""
    Q = model.random_configurations(256, rng)
    for q in Q:  # warm up
        fk_jacobian(model, data, q)
    times = np.empty(calls)
    clock = time.perf_counter_ns
    for k in range(calls):
        q = Q[k & 255]
        t0 = clock()
        fk_jacobian(model, data, q)
        times[k] = clock() - t0
    return float(np.median(times)) / 1e3


def bench_batch(model, rng, n: int = 10000, repeats: int = 30) -> float:
    """Median configurations per second of fk_batch over n configurations."""
    Q = model.random_configurations(n, rng)
    out = np.empty((n, 4, 4))
    fk_batch(model, Q, out=out)
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fk_batch(model, Q, out=out)
        rates.append(n / (time.perf_counter() - t0))
    return statistics.median(rates)


def bench_ik(model, data, rng, poses: int) -> tuple[float, float, float, float]:
    """(success rate, max position error m, max rotation error rad, median ms per solve)."""
    Q = model.random_configurations(poses, rng)
    targets = fk_batch(model, Q)
    seeds = Q + rng.uniform(0.1, 0.3, Q.shape) * rng.choice([-1.0, 1.0], Q.shape)
    sols = np.empty_like(Q)
    ok = np.zeros(poses, dtype=bool)
    times = np.empty(poses)
    for k in range(poses):
        t0 = time.perf_counter()
        r = solve_ik(model, data, targets[k], seeds[k])
        times[k] = time.perf_counter() - t0
        sols[k], ok[k] = r.q, r.success
    pos, ang = pose_errors_batch(targets, fk_batch(model, sols))
    good = ok & (pos <= TARGET_IK_ERR) & (ang <= TARGET_IK_ERR)
    return float(good.mean()), float(pos.max()), float(ang.max()), float(np.median(times) * 1e3)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ik-poses", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)

    print(f"machine : {platform.platform()} | {cpu_model()} | {platform.machine()}")
    import os
    print(f"python  : {platform.python_version()} | numpy {np.__version__} | "
          f"cores {os.cpu_count()} | loadavg {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    rows = []

    def row(arm: str, figure: str, measured: str, target: str, passed: bool) -> None:
        rows.append((arm, figure, measured, target, "pass" if passed else "FAIL"))

    for name in ARMS:
        model = load_model(ROOT / "configs" / "arm" / f"{name}.toml")
        data = KinematicData(model)
        us = bench_fkj(model, data, rng)
        row(name, "FK+Jacobian single call (median)", f"{us:.1f} us", f"<= {TARGET_FKJ_US:.0f} us",
            us <= TARGET_FKJ_US)
        cps = bench_batch(model, rng)
        row(name, "vectorised FK, 10,000 configs (median)", f"{cps / 1e6:.2f} M configs/s",
            ">= 1.00 M configs/s", cps >= TARGET_BATCH_CPS)
        rate, pos, ang, ms = bench_ik(model, data, rng, args.ik_poses)
        row(name, f"IK success, {args.ik_poses} poses, nearby seed", f"{rate:.2%}",
            f">= {TARGET_IK_RATE:.1%}", rate >= TARGET_IK_RATE)
        row(name, "IK final error max (position)", f"{pos:.1e} m", "<= 1e-06 m", pos <= TARGET_IK_ERR)
        row(name, "IK final error max (rotation)", f"{ang:.1e} rad", "<= 1e-06 rad",
            ang <= TARGET_IK_ERR)
        row(name, "IK time per solve (median)", f"{ms:.3f} ms", f"<= {TARGET_IK_MS:.0f} ms",
            ms <= TARGET_IK_MS)

    return print_table(rows)


def print_table(rows: list[tuple[str, str, str, str, str]]) -> int:
    """Print the result table (rows judged "-" are references) and return the exit code."""
    headers = ("arm", "figure", "measured", "target", "result")
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]
    line = "  ".join(h.ljust(w) for h, w in zip(headers, widths))
    print()
    print(line)
    print("-" * len(line))
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)))
    judged = [r for r in rows if r[4] != "-"]
    failed = sum(r[4] == "FAIL" for r in judged)
    print(f"\n{len(judged) - failed}/{len(judged)} targets met")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
