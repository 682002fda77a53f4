"""Sim-vs-real diagnosis on a real recording: the Franka Emika Panda exciting trajectory of
Gaz et al. (RA-L 2019), from ../shared/data/panda_gaz2019 (GPL-3.0 data: read, not copied).

    .venv/bin/python bench/bench_diagnosis_real.py

Runs `spacearm diagnose REC --urdf configs/urdf/panda/panda_arm_no_hand.urdf --command measured
--rate 100 --heldout-from 14.5` (the recording has no commanded position; 1 kHz with jitter,
repeats and gaps, resampled to 100 Hz) and prints, per joint, the held-out (t >= 14.5 s) torque
RMS of the URDF rigid-body model before and after the findings, beside the published model
evaluated on the same rows (Gaz et al.'s M, c, g plus their Table I friction; the data
folder's README), and the fitted Coulomb friction beside their Table III (CLS, and RE). A second run
with the URDF that still carries the hand (0.73 kg + 2 x 0.015 kg the recording lacks) must
name a payload error of about -0.76 kg.
"""
from __future__ import annotations

import csv
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.offline.diagnosis.arm_torque import diagnose_arm  # noqa: E402
from spacearm.offline.diagnosis.recording_io import read_recording  # noqa: E402
from spacearm.offline.diagnosis.rigid_body import load_arm  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "panda_gaz2019"
ARM = ROOT / "configs/urdf/panda/panda_arm_no_hand.urdf"
ARM_WITH_HAND = ROOT / "configs/urdf/panda/panda.urdf"
HELDOUT_FROM = 14.5
# README of the data folder, "same, held-out t >= 14.5 s": Gaz M q'' + c + g + Table I friction
PUBLISHED_HELDOUT = (0.42, 0.84, 0.45, 0.52, 0.15, 0.14, 0.07)
HAND_MASS = 0.73 + 2 * 0.015


def published_coulomb(method: str = "CLS") -> list[float]:
    """Table III's Coulomb level by classical least squares (CLS, the issue's reference) or RE."""
    with open(DATA / "published_friction.csv", newline="") as f:
        return [float(r[f"fc_{method}_Nm"]) for r in csv.DictReader(f)]


def run(urdf: Path = ARM):
    table, _ = read_recording(DATA / "exciting_traj_1.csv", None, "measured", 0.01)
    started = time.perf_counter()
    result = diagnose_arm(table, load_arm(urdf, table.n_joints), HELDOUT_FROM)
    return result, time.perf_counter() - started


def main() -> dict:
    if not (DATA / "exciting_traj_1.csv").exists():
        print(f"no data at {DATA}: nothing measured")
        return {}
    result, elapsed = run()
    fc, fc_re = published_coulomb(), published_coulomb("RE")
    print(f"Panda (Gaz et al. 2019) exciting trajectory 1, held-out t >= {HELDOUT_FROM} s, "
          f"{platform.node()}, load {os.getloadavg()[0]:.2f}, diagnosis {elapsed:.2f} s")
    print("| joint | URDF rigid body | with findings | published model + friction | Coulomb fitted +-95 % "
          "| published fc CLS (RE) | off CLS | findings |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    out = {"joints": []}
    for j in result.joints:
        f = next((f for f in result.findings if f.joint == j.joint), None)
        c = f.params.get("coulomb_friction") if f else None
        ce = 1.96 * f.stderr.get("coulomb_friction", float("nan")) if c is not None else None
        print(f"| {j.joint + 1} | {j.rms_nominal:.3f} | {j.rms_fitted:.3f} | {PUBLISHED_HELDOUT[j.joint]:.2f} | "
              + (f"{c:.3f} +- {ce:.3f}" if c is not None else "-") + f" | {fc[j.joint]:.3f} ({fc_re[j.joint]:.3f}) | "
              + (f"{100 * (c / fc[j.joint] - 1):+.0f} %" if c is not None else "-") + " | "
              + ("+".join(f.effects) if f else "none") + " |")
        out["joints"].append({"joint": j.joint + 1, "before": j.rms_nominal, "after": j.rms_fitted,
                              "published": PUBLISHED_HELDOUT[j.joint], "coulomb": c, "published_fc": fc[j.joint]})
    better = sum(j.rms_fitted <= p for j, p in zip(result.joints, PUBLISHED_HELDOUT))
    named = sum(1 for f in result.findings if f.joint is not None and "coulomb" in f.effects)
    within = sum(1 for j in out["joints"] if j["coulomb"] is not None
                 and abs(j["coulomb"] - j["published_fc"]) <= 0.15 * j["published_fc"])
    offset = result.time_offset
    print(f"Coulomb friction within 15 % of the published CLS value on {within}/7 joints (target 6/7); torque "
          f"column re-aligned by {1e3 * offset.seconds if offset else 0.0:+.1f} ms"
          + (f" (p = {offset.p_value:.2g})" if offset else "")
          + f"; velocity column dq {1e3 * result.velocity_lag.seconds if result.velocity_lag else 0.0:+.1f} ms behind "
            "the position column q (from dq/dt of q; named, not re-aligned)")
    print(f"held-out torque RMS at or below the published model's on {better}/7 joints (target 7/7); "
          f"Coulomb friction named on {named}/7 joints (published: all 7)")
    rb = [f.text for f in result.findings if f.joint is None]
    print("coupled: " + (rb[0] if rb else "none"))
    hand, _ = run(ARM_WITH_HAND)
    payload = next((f for f in hand.findings if f.effects == ("payload",)), None)
    mass = payload.params["payload_mass"] if payload else float("nan")
    print(f"URDF with the hand the recording lacks: payload error {mass:+.3f} kg named "
          f"(truth {-HAND_MASS:+.3f} kg, {100 * abs(mass + HAND_MASS) / HAND_MASS:.0f} % off; target <= 15 %)")
    out.update(better=better, named=named, within=within, payload=mass, seconds=elapsed)
    return out


if __name__ == "__main__":
    main()
