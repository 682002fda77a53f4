"""Sim-vs-real diagnosis on concealed effects: generator, scorer, table by effect type.

    .venv/bin/python bench/bench_diagnosis.py [--cases 60] [--duration 60] [--seed 0] [--no-timing]
                                              [--workers N | --scheduler tcp://H:P] [--results DIR --resume]

Each case is one trial of a campaign (kind `diagnosis`, offline/campaign/kind_diagnosis.py) run
on Dask: `run_case(effects, seed, ...)` below is the per-case entry point, the case types follow
CASE_MIX in turn (the campaign's [levels.effects]) and each case draws everything else from its
own trial seed; the table is printed from the campaign's Parquet rows.

The generator draws hidden plants (none, one or two effects from the catalogue, random joint
or F/T axis, random size from clearly visible down to below the noise), random trajectories
(multi-sine, point-to-point moves with rests, slow one-way ramps that rarely reverse), sensor
noise on (resolver quantisation, 0.5 N m torque noise, 0.3 N / 0.01 N m F/T noise). It
writes each recording (wide CSV) to one directory and the truth (JSON) to another; the
diagnosis reads only the CSV, the scorer alone reads the truth.

Recordings use the direct simulation path (same plant and drive servo law as the CAN path;
tests/diagnosis/test_direct_vs_can.py shows they agree); one 5-minute recording is timed
end to end (read CSV, replay, fit, re-simulate, report).

Visibility of an effect = RMS over the recording of (noise-free truth - noise-free nominal)
on the affected channel, divided by that channel's noise (MAD of row-to-row differences of
a noisy nominal recording). "Above 2x noise" means visibility >= 2.
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.offline.diagnosis.analysis import diagnose, noise_level  # noqa: E402
from spacearm.offline.diagnosis.direct_sim import simulate  # noqa: E402
from spacearm.offline.diagnosis.record import record_direct, starting_at  # noqa: E402
from spacearm.offline.diagnosis.recording_io import read_table  # noqa: E402
from spacearm.offline.diagnosis.report import write_report  # noqa: E402
from spacearm.offline.diagnosis.trajectory import Trajectory  # noqa: E402
from spacearm.controller.recording.csv_export import WRENCH_COLUMNS  # noqa: E402
from spacearm.firmware_sim.plant import PlantConfig, load_plant_config  # noqa: E402

NOMINAL = ROOT / "configs/plant/oru_testbed_nominal.toml"
DT = 0.02
Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])
VMAX = 0.12          # rad/s, below the arm file's 10 deg/s limit
# torque_saturation is in the catalogue but not drawn: these gentle trajectories (<= 0.12 rad/s)
# need about 1 N m of smooth torque, so a limit either clips only resolver chatter or stalls the arm
JOINT_EFFECTS = ("coulomb", "viscous", "stribeck", "gravity_load", "latency", "backlash", "elasticity")
FT_EFFECTS = ("ft_bias", "ft_drift")
EFFECTS = JOINT_EFFECTS + FT_EFFECTS
# main parameter scored against the truth, per effect
MAIN_PARAMETER = {"coulomb": "coulomb_friction", "viscous": "viscous_friction", "stribeck": "stribeck_friction",
                  "gravity_load": "gravity_torque", "torque_saturation": "torque_limit_joint",
                  "latency": "feedback_latency_cycles", "ft_bias": "bias", "ft_drift": "drift",
                  "backlash": "backlash", "elasticity": "joint_stiffness"}


# ------------------------------------------------------------------ generator
def noisy(config: PlantConfig, seed: int) -> PlantConfig:
    joints = [(config.joints[i] if i < len(config.joints) else config.joint).model_copy(update={"torque_noise": 0.5})
              for i in range(6)]
    return config.model_copy(update={"joints": joints, "seed": seed,
                                     "ft": config.ft.model_copy(update={"noise_force": 0.3, "noise_torque": 0.01})})


def quiet(config: PlantConfig) -> PlantConfig:
    joints = [j.model_copy(update={"torque_noise": 0.0, "resolver_arcsec": 0.0}) for j in config.joints]
    return config.model_copy(update={"joints": joints,
                                     "ft": config.ft.model_copy(update={"noise_force": 0.0, "noise_torque": 0.0})})


def random_trajectory(rng: np.random.Generator, duration: float) -> tuple[str, Trajectory]:
    t = np.arange(0.0, duration, DT)
    kind = rng.choice(["sines", "moves", "one_way"], p=[0.5, 0.3, 0.2])
    # start anywhere near home: on or off the resolver grid, as a real arm would be
    q = np.repeat((Q_HOME + rng.uniform(-0.05, 0.05, 6))[None, :], len(t), axis=0)
    for j in range(6):
        if kind == "sines":
            for _ in range(2):
                period = rng.uniform(4.0, 20.0)
                amp = rng.uniform(0.2, 0.5) * VMAX * period / (2 * math.pi)
                q[:, j] += amp * np.sin(2 * math.pi * t / period + rng.uniform(0, 2 * math.pi))
        elif kind == "moves":
            pieces, pos, count = [], 0.0, 0
            while count < len(t):
                rest = np.full(int(rng.uniform(0.5, 4.0) / DT), pos)
                target = rng.uniform(-0.25, 0.25)
                s_ = np.linspace(0.0, 1.0, int(max(abs(target - pos) / (0.5 * VMAX), 1.0) / DT))
                move = pos + (target - pos) * (10 * s_ ** 3 - 15 * s_ ** 4 + 6 * s_ ** 5)   # quintic, peak 0.94 VMAX
                pieces += [rest, move]
                count += len(rest) + len(move)
                pos = target
            q[:, j] += np.concatenate(pieces)[:len(t)]
        else:   # slow one-way ramp: velocity never reverses, little to see from friction
            speed = rng.uniform(0.01, 0.4) * VMAX * rng.choice([-1, 1])
            q[:, j] += speed * t
    return str(kind), Trajectory(t, q)


@dataclass
class Truth:
    effect: str
    index: int              # joint (0-based) or F/T axis
    params: dict[str, float]
    visibility: float = 0.0
    channel: str = ""


@dataclass
class Case:
    name: str
    kind: str               # none | one | two
    trajectory: str
    truths: list[Truth] = field(default_factory=list)


class ChannelNoise:
    """Noise of each channel for one trajectory, as the tool would see it: noisy minus quiet
    nominal recording, row-to-row scatter. Joint channels from single-joint runs (joints are
    independent), F/T from its configured noise and counts."""

    def __init__(self, nominal: PlantConfig, traj: Trajectory, seed: int):
        self.nominal, self.traj, self.seed = nominal, traj, seed
        self._cache: dict[str, float] = {}

    def __getitem__(self, name: str) -> float:
        if name not in self._cache:
            if name in WRENCH_COLUMNS:
                ft = noisy(self.nominal, 0).ft
                sigma, quantum = (ft.noise_force, 0.01) if name.startswith("f") else (ft.noise_torque, 0.001)
                self._cache[name] = math.sqrt(sigma ** 2 + quantum ** 2 / 12.0)
            else:
                j = int(name.split("_")[1]) - 1
                a = simulate(starting_at(noisy(self.nominal, self.seed), self.traj.q[0]), self.traj.q, DT, joints=[j])
                b = simulate(starting_at(quiet(self.nominal), self.traj.q[0]), self.traj.q, DT, joints=[j])
                self._cache[f"tau_{j + 1}"] = noise_level(a.tau[:, 0] - b.tau[:, 0])
                self._cache[f"q_{j + 1}"] = max(noise_level(a.q[:, 0] - b.q[:, 0]), 25 * 4.8481368e-6 / math.sqrt(12))
        return self._cache[name]


def draw_effect(rng: np.random.Generator, effect: str, used: set, duration: float, traj: Trajectory,
                noise: dict[str, float]) -> Truth:
    if effect in FT_EFFECTS:
        index = int(rng.choice([i for i in range(6) if ("ft", i) not in used]))
        used.add(("ft", index))
        sigma = noise[WRENCH_COLUMNS[index]]
        size = sigma * math.exp(rng.uniform(math.log(0.5), math.log(10.0)))
        params = {"bias": size} if effect == "ft_bias" else {"drift": size / (0.6 * duration)}
        return Truth(effect, index, params, channel=WRENCH_COLUMNS[index])
    index = int(rng.choice([j for j in range(6) if ("joint", j) not in used]))
    used.add(("joint", index))
    sigma = noise[f"tau_{index + 1}"]
    factor = math.exp(rng.uniform(math.log(0.5), math.log(10.0)))
    v = np.gradient(traj.q[:, index], DT)
    if effect == "coulomb":
        params = {"coulomb_friction": factor * sigma}
    elif effect == "viscous":
        params = {"viscous_friction": factor * sigma / max(float(np.sqrt(np.mean(v ** 2))), 0.01)}
    elif effect == "stribeck":
        params = {"stribeck_friction": 2.0 * factor * sigma, "stribeck_velocity": float(rng.uniform(0.004, 0.03))}
    elif effect == "gravity_load":
        params = {"gravity_torque": factor * sigma, "gravity_angle": float(rng.uniform(-math.pi, math.pi))}
    elif effect == "torque_saturation":
        tau = np.abs(simulate(quiet(load_plant_config(NOMINAL)), traj.q, DT, joints=[index]).tau[:, 0])
        params = {"torque_limit_joint": float(tau.max() * rng.uniform(0.3, 0.9))}
    elif effect == "backlash":        # 0.4 .. 5 mrad of play (3 .. 40 resolver quanta)
        params = {"backlash": float(math.exp(rng.uniform(math.log(4e-4), math.log(5e-3))))}
    elif effect == "elasticity":      # 3e4 .. 1e6 N m/rad: from ringing to barely there
        params = {"joint_stiffness": float(math.exp(rng.uniform(math.log(3e4), math.log(1e6))))}
    else:
        params = {"feedback_latency_cycles": int(rng.integers(1, 4))}
    return Truth(effect, index, params, channel="q" if effect == "latency" else "tau")


def apply_truth(config: PlantConfig, truths: list[Truth]) -> PlantConfig:
    joints = [config.joints[i] if i < len(config.joints) else config.joint for i in range(6)]
    bias, drift = list(config.ft.bias), list(config.ft.drift)
    for tr in truths:
        if tr.effect == "ft_bias":
            bias[tr.index] += tr.params["bias"]
        elif tr.effect == "ft_drift":
            drift[tr.index] += tr.params["drift"]
        else:
            p = dict(tr.params)
            if "torque_limit_joint" in p:
                p = {"torque_limit": p.pop("torque_limit_joint") / joints[tr.index].gear_ratio}
            joints[tr.index] = joints[tr.index].model_copy(update=p)
    return config.model_copy(update={"joints": joints, "ft": config.ft.model_copy(
        update={"bias": tuple(bias), "drift": tuple(drift)})})


def visibility(nominal: PlantConfig, truth_plant: PlantConfig, traj: Trajectory, tr: Truth,
               noise: ChannelNoise) -> float:
    t = traj.t - traj.t[0]
    if tr.effect == "ft_bias":
        return abs(tr.params["bias"]) / noise[WRENCH_COLUMNS[tr.index]]
    if tr.effect == "ft_drift":
        return float(np.sqrt(np.mean((tr.params["drift"] * t) ** 2))) / noise[WRENCH_COLUMNS[tr.index]]
    a = simulate(starting_at(quiet(truth_plant), traj.q[0]), traj.q, DT, joints=[tr.index])
    b = simulate(starting_at(quiet(nominal), traj.q[0]), traj.q, DT, joints=[tr.index])
    if tr.effect == "latency":
        d, name = a.q[:, 0] - b.q[:, 0], f"q_{tr.index + 1}"
    else:
        d, name = a.tau[:, 0] - b.tau[:, 0], f"tau_{tr.index + 1}"
    return float(np.sqrt(np.mean(d ** 2)) / noise[name])


CASE_TYPES = {0: "none", 1: "one", 2: "two"}     # hidden effects per case
CASE_MIX = (1, 1, 1, 2, 0)                        # the bench's cases in turn: 60 % one, 20 % two, 20 % none


def generate_case(effects: int, duration: float, seed: int, name: str, rec_dir: Path, truth_dir: Path) -> Path:
    """One hidden plant + random trajectory + noisy recording (rec_dir/NAME.csv) and its truth
    (truth_dir/NAME.json), all drawn from `seed`; returns the recording."""
    if effects not in CASE_TYPES:
        raise ValueError(f"effects per case: expected 0, 1 or 2, got {effects!r}")
    rng = np.random.default_rng(seed)
    nominal = load_plant_config(NOMINAL)
    traj_kind, traj = random_trajectory(rng, duration)
    noise = ChannelNoise(nominal, traj, seed * 1000)
    used: set = set()
    drawn = list(rng.choice(EFFECTS, size=effects, replace=False)) if effects else []
    truths = [draw_effect(rng, e, used, duration, traj, noise) for e in drawn]
    plant = apply_truth(nominal, truths)
    for tr in truths:
        tr.visibility = visibility(nominal, apply_truth(nominal, [tr]), traj, tr, noise)
    path = rec_dir / f"{name}.csv"
    record_direct(noisy(plant, seed * 1000 + 1), traj, path, hold_cycles=0)
    case = Case(name, CASE_TYPES[effects], traj_kind, truths)
    (truth_dir / f"{name}.json").write_text(json.dumps({
        "name": name, "kind": case.kind, "trajectory": traj_kind,
        "truths": [vars(t) for t in case.truths]}, indent=1))
    return path


def run_case(effects: int, seed: int, duration: float, work: Path, name: str) -> tuple["Score", dict[str, float]]:
    """The per-case entry point (campaign kind `diagnosis`): generate one case into
    work/{recordings,truth}, diagnose the recording alone into work/reports/NAME, score it
    against the truth. Returns the score and the wall times of generation and analysis (s)."""
    dirs = [work / d for d in ("recordings", "truth", "reports")]
    for d in dirs:
        d.mkdir(parents=True, exist_ok=True)
    rec_dir, truth_dir, rep_dir = dirs
    t0 = time.perf_counter()
    path = generate_case(effects, duration, seed, name, rec_dir, truth_dir)
    t1 = time.perf_counter()
    nominal = load_plant_config(NOMINAL)             # the tool's side: the recording only
    summary = write_report(diagnose(read_table(path), nominal), rep_dir / name, path.name, nominal)
    t2 = time.perf_counter()
    score = score_case(summary, json.loads((truth_dir / f"{name}.json").read_text()))   # the scorer's side
    return score, {"generation_time": t1 - t0, "analysis_time": t2 - t1}


# ------------------------------------------------------------------ scorer
@dataclass
class Score:
    name: str
    kind: str
    effects: list[str]
    visible: bool                       # every effect >= 2x noise
    named: bool                         # correct effect(s) and location named first
    false_alarm: bool
    param_ok: list[bool]
    rms_reduction: list[float]
    answer: str
    why: str = ""


def _finding_matches(f: dict, tr: dict) -> bool:
    if tr["effect"] not in f["effects"]:
        return False
    if tr["effect"] in FT_EFFECTS:
        return f["axis"] == tr["index"]
    return f["joint"] == tr["index"] + 1


def score_case(summary: dict, truth: dict) -> Score:
    findings = summary["findings"]
    truths = truth["truths"]
    answer = " | ".join([f["text"] for f in findings] + [f"unexplained {c}" for c in summary["unexplained_channels"]]) \
        or "no significant mismatch"
    effects = [t["effect"] for t in truths]
    visible = bool(truths) and all(t["visibility"] >= 2.0 for t in truths)
    if not truths:
        alarm = bool(findings or summary["unexplained_channels"])
        return Score(truth["name"], "none", [], False, not alarm, alarm, [], [], answer, "false alarm" if alarm else "")
    top = findings[:len(truths)]
    named = all(any(_finding_matches(f, t) for f in top) for t in truths)
    param_ok, reductions = [], []
    for t in truths:
        match = next((f for f in findings if _finding_matches(f, t)), None)
        key = MAIN_PARAMETER[t["effect"]]
        if match is not None and key in match["parameters"]:
            true, fitted = t["params"][key], match["parameters"][key]
            param_ok.append(abs(fitted - true) <= 0.15 * abs(true))
        channel = t["channel"] if t["effect"] in FT_EFFECTS else f"{t['channel']}_{t['index'] + 1}"
        ch = next(c for c in summary["channels"] if c["name"] == channel)
        reductions.append(1.0 - ch["heldout_rms_after"] / ch["heldout_rms_before"] if ch["heldout_rms_before"] else 0.0)
    why = ""
    if not named:
        vis = ", ".join(f"{t['effect']} j/axis {t['index'] + 1 if t['effect'] not in FT_EFFECTS else t['channel']} "
                        f"at {t['visibility']:.1f}x noise" for t in truths)
        why = f"truth {vis}; trajectory {truth['trajectory']}"
    return Score(truth["name"], truth["kind"], effects, visible, named, False, param_ok, reductions, answer, why)


# ------------------------------------------------------------------ table
def table(scores: list[Score]) -> None:
    print(f"\n{'effect / case type':<22}{'cases':>6}{'>=2x':>6}{'named 1st (>=2x)':>18}{'named 1st (all)':>17}"
          f"{'param 15%':>11}{'RMS red. median':>17}")
    rows = [(e, [s for s in scores if s.kind == "one" and s.effects == [e]]) for e in EFFECTS]
    rows += [("one effect (all)", [s for s in scores if s.kind == "one"]),
             ("two effects", [s for s in scores if s.kind == "two"])]
    for label, group in rows:
        if not group:
            continue
        vis = [s for s in group if s.visible]
        named_vis = f"{sum(s.named for s in vis)}/{len(vis)}" + (f" {100 * np.mean([s.named for s in vis]):.0f}%"
                                                                 if vis else "")
        named_all = f"{sum(s.named for s in group)}/{len(group)}"
        params = [p for s in group if s.named for p in s.param_ok]
        par = f"{sum(params)}/{len(params)}" + (f" {100 * np.mean(params):.0f}%" if params else "")
        red = [r for s in group if s.named for r in s.rms_reduction]
        red_s = f"{100 * np.median(red):.0f}%" if red else "-"
        print(f"{label:<22}{len(group):>6}{len(vis):>6}{named_vis:>18}{named_all:>17}{par:>11}{red_s:>17}")
    nulls = [s for s in scores if s.kind == "none"]
    if nulls:
        fa = sum(s.false_alarm for s in nulls)
        print(f"{'no effect (false alarm)':<22}{len(nulls):>6}{'':>6}{f'{fa}/{len(nulls)} {100 * fa / len(nulls):.0f}%':>18}")


def score_from_row(row: dict) -> Score:
    """A campaign result row (kind `diagnosis`) back as the Score the table counts."""
    effects = [e for e in (row.get("l_effect_names") or "").split(",") if e]
    return Score(row["trial_id"], row.get("l_case_type") or "?", effects, bool(row.get("f_visible")),
                 bool(row.get("f_named_first")), bool(row.get("f_false_alarm")),
                 [bool(p) for p in row.get("s_param_ok") or []], list(row.get("s_rms_reduction") or []),
                 row.get("l_answer") or "", row.get("l_why") or (row.get("error") or ""))


def run_cases(args, keep: Path | None, results: Path) -> tuple[list[Score], list[dict], object]:
    """The cases as a campaign (kind `diagnosis`) on Dask: one trial per case, Parquet rows."""
    from spacearm.offline.campaign.runner import run_campaign
    from spacearm.offline.campaign.schema import campaign_from_text, campaign_text
    from spacearm.offline.campaign.store import ResultStore

    text = campaign_text("bench_diagnosis", "diagnosis", args.seed, args.cases, levels={"effects": list(CASE_MIX)},
                         options={"duration": float(args.duration), "keep": str(keep.resolve()) if keep else ""})
    campaign = campaign_from_text(text, "bench/bench_diagnosis.py")
    summary = run_campaign(campaign, results, args.scheduler, args.workers, args.resume)
    rows = ResultStore(results).rows()
    return [score_from_row(r) for r in rows], rows, summary


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--duration", type=float, default=60.0, help="s per recording")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-timing", action="store_true", help="skip the 5-minute timing case")
    ap.add_argument("--keep", type=Path, default=None, help="keep recordings/truths/reports here")
    ap.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: one per core)")
    ap.add_argument("--scheduler", default=None, help="tcp://HOST:PORT of a running Dask scheduler")
    ap.add_argument("--results", type=Path, default=None, help="campaign result directory (default: KEEP/campaign "
                                                                "or a temporary one)")
    ap.add_argument("--resume", action="store_true", help="continue the campaign in --results")
    args = ap.parse_args(argv)
    work = tempfile.TemporaryDirectory()
    base = args.keep or Path(work.name)
    results = args.results or base / "campaign"
    print(f"machine : {platform.platform()} | {platform.machine()} | python {platform.python_version()} "
          "(2 cores shared with other jobs: timings are under load)")
    print(f"cases   : {args.cases} x {args.duration:.0f} s at 50 Hz, seed {args.seed}, direct simulation path, "
          f"one campaign trial each (kind diagnosis, results {results})")
    from spacearm.offline.campaign.store import StoreError
    try:
        scores, rows, summary = run_cases(args, args.keep, results)
    except StoreError as exc:                 # e.g. a finished campaign in --results without --resume
        raise SystemExit(f"error: {exc}") from None
    table(scores)
    gen = [r["w_generation_time"] for r in rows if r.get("w_generation_time") is not None]
    analysis = [r["w_analysis_time"] for r in rows if r.get("w_analysis_time") is not None]
    broken = [r["trial_id"] for r in rows if r["error"]]
    print(f"\ncampaign: {summary.ran} cases in {summary.wall_time:.0f} s on {summary.workers} workers "
          f"({summary.scheduler}); {summary.skipped} done before; {len(broken)} broken {broken or ''}")
    if analysis:
        print(f"generation per case median {np.median(gen):.1f} s; analysis per {args.duration:.0f} s recording: "
              f"median {np.median(analysis):.1f} s, max {max(analysis):.1f} s (incl. plots and report)")
    misses = [s for s in scores if (s.kind != "none" and not s.named) or s.false_alarm]
    if misses:
        print("\nmisses:")
        for s in misses:
            print(f"  {s.name} [{s.kind}{', >=2x' if s.visible else ', <2x noise'}] {s.why or 'false alarm'}"
                  f"\n      tool said: {s.answer}")
    nominal = load_plant_config(NOMINAL)
    rec_dir, rep_dir = base / "recordings", base / "reports"
    for d in (rec_dir, rep_dir):
        d.mkdir(parents=True, exist_ok=True)
    out = {"scores": [vars(s) for s in scores]}
    if not args.no_timing:
        rng = np.random.default_rng(args.seed + 99)
        _, traj = random_trajectory(rng, 300.0)
        truths = [Truth("coulomb", 2, {"coulomb_friction": 4.0}, channel="tau")]
        path = rec_dir / "timing_5min.csv"
        record_direct(noisy(apply_truth(nominal, truths), 5), traj, path, hold_cycles=0)
        t1 = time.perf_counter()
        result = diagnose(read_table(path), nominal)
        write_report(result, rep_dir / "timing_5min", path.name, nominal)
        elapsed = time.perf_counter() - t1
        print(f"\n5-minute recording at 50 Hz (15000 cycles), read + replay + fit + re-simulate + report: "
              f"{elapsed:.1f} s (target <= 60 s) -> {result.verdict}")
        out["timing_5min_s"] = elapsed
    return out


if __name__ == "__main__":
    main()
