"""Calibration benchmarks: configuration selection vs random subsets, identification speed,
the laser and EKF headline numbers (small Monte-Carlo sizes by default; --full for the studies).

    .venv/bin/python bench/bench_calibration.py [--full]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from spacearm.controller.calibration import Problem, lm
from spacearm.controller.calibration import study_ekf as E
from spacearm.controller.calibration import study_laser as L
from spacearm.controller.calibration.studies import ekf_study, laser_study


def bench_selection() -> None:
    st = L.setup()
    print("Configuration selection (laser arm, 101 candidates, O3), greedy + exchange vs 10,000 random subsets")
    for m in (50, 100):
        for seed in (0, 1, 2):
            b = L.selection_benchmark(st, m, seed=seed)
            verdict = "ok" if (b["ratio"] >= 1.2 and b["seconds"] <= 5.0) else (
                "n/a: only 101 subsets of size 100 exist" if m == 100 else "MISS")
            print(f"  m={m:3d} seed={seed}: selected {b['selected_O3']:.4f}, random best {b['random_best_O3']:.4f}, "
                  f"ratio {b['ratio']:.3f}, {b['seconds']:.2f} s  [{verdict}]")


def bench_identification_speed(reps: int = 20) -> None:
    st = E.setup()
    rng = np.random.default_rng(0)
    Q = E.nonsingular_configurations(st, 50, rng)
    meas = E.measure(st.model.poses(st.x_true, Q + rng.normal(0, st.control_sigma, Q.shape)),
                     0.3e-3, np.radians(0.5), rng)
    cov = E.pose_covariances(st, Q, 0.3e-3, np.radians(0.5))
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        lm(Problem(st.model, "pose", Q, meas, st.free, cov=cov), sigma_prior=E.prior_sigma(st))
        times.append(time.perf_counter() - t0)
    print(f"Identification of {len(st.free)} parameters from 50 postures (full-cov MAP LM): "
          f"median {np.median(times) * 1e3:.1f} ms, max {np.max(times) * 1e3:.1f} ms (target <= 200 ms)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--full", action="store_true", help="run the full studies (20 / 10 runs)")
    args = ap.parse_args()
    bench_selection()
    bench_identification_speed()
    runs_l, runs_e = (20, 10) if args.full else (5, 3)
    text, head = laser_study(runs=runs_l)
    print(text)
    for m, lim in ((100, 0.08), (50, 0.15)):
        worst = max(head["rms_pos_mm"][m])
        print(f"laser {m} configs: worst-axis RMS position {worst:.4f} mm (target <= {lim})")
    print(f"laser 100 configs: worst-axis max position {max(head['max_pos_mm'][100]):.4f} mm (target <= 0.3), "
          f"worst-axis RMS orientation {max(head['rms_rot_mrad'][100]):.4f} mrad (target <= 0.25)")
    text, head = ekf_study(runs=runs_e, counts=(10, 50, 200), count_reps=3)
    print(text)
    best = min(head["ratios"], key=head["ratios"].get)
    print(f"EKF study: best method {best}, mean position error / floor = {head['ratios'][best]:.3f} (target <= 1.10)")


if __name__ == "__main__":
    main()
