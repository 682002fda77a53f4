"""Campaign runner benchmark: throughput with 1 and 2 Dask workers, scheduler overhead per trial,
a campaign killed half-way and resumed, and the same seeds giving the same results locally, on
the network-namespace cluster and replayed alone. Prints one table.

    .venv/bin/python bench/bench_campaign.py [--trials 12] [--rounds 2] [--cheap-trials 40] [--skip-netns]
        [--against DIR]

--against DIR: another checkout with its own .venv (set up by its `./scripts/run_tests.sh --co -q`),
e.g. issue 35's tree 9e80b96 (`git worktree add DIR 9e80b96`): the same insertion campaign on 2
workers through each tree's own `spacearm campaign run`, the trees alternating `--rounds` times,
trials per minute of each, their ratio, and whether each seed gave the same result in both.

Throughput uses the insertion trial of bench_oru (seconds each); the overhead and the
kill/resume use the cheap EKF calibration trial (~0.05 s), where the scheduler's share shows.
Overhead per trial = (first submit -> last result written) / trials - mean task time, one worker.

Where one insertion trial's time goes (insertion_smoke trial 0, 570 cycles of 10 contact
sub-steps; cProfile own time by module after a warm-up trial, load 13; CPU without the profiler):

| part | 9e80b96 (2.25 s CPU) | wave-camp8 (0.97 s CPU) |
|---|---|---|
| contact world: pose, contacts, sums a sub-step (firmware_sim/contact/world.py) | 24 % | 24 % |
| contact of a box in a slot or guide (firmware_sim/contact/cavity.py) | 19 % | 22 % |
| numpy's C calls and Python wrappers (small arrays) | 32 % | 21 % |
| joints' sub-steps: servo law, friction, integration (firmware_sim/plant.py, joint_drive) | 13 % | 12 % |
| forward kinematics and Jacobian a sub-step (base/kinematics) | 7 % | 12 % |
| impedance mode, its IK and the F/T read (controller/impedance, direct_loop) | 5 % | 9 % |

A worker's first trial also imports the trial's modules (~0.6 s CPU, a third of it scipy's
Rotation that controller/planning/cartesian_path.py imports for linear_move's `quintic`).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hil_tests.harness import CpuSteal  # noqa: E402
from spacearm.offline.campaign.replay import replay  # noqa: E402
from spacearm.offline.campaign.runner import RunSummary, run_campaign  # noqa: E402
from spacearm.offline.campaign.schema import load_campaign  # noqa: E402
from spacearm.offline.campaign.store import ResultStore  # noqa: E402

INSERTION = ROOT / "configs/campaigns/insertion_smoke.toml"
EKF = ROOT / "configs/campaigns/calibration_ekf.toml"
Row = tuple[str, str, str, str]      # figure, measured, target, load / steal


def with_trials(source: Path, trials: int, out: Path) -> Path:
    text = source.read_text()
    lines = [f"trials = {trials}" if line.startswith("trials =") else line for line in text.splitlines()]
    out.write_text("\n".join(lines) + "\n")
    return out


def conditions(steal: CpuSteal) -> str:
    return f"load {os.getloadavg()[0]:.1f}, steal {100 * steal.fraction():.1f} %"


def deterministic(results: Path) -> dict:
    return ResultStore(results).outcomes()


def task_times(results: Path) -> np.ndarray:
    return np.array([r["w_task_wall_time"] for r in ResultStore(results).rows()])


def throughput(work: Path, trials: int, rounds: int, steal: CpuSteal) -> tuple[list[Row], dict[int, Path]]:
    """1 and 2 workers in turn, `rounds` times: the machine's other load drifts between runs, so
    each round's pair is taken close together and the best rate of each count is compared."""
    campaign = load_campaign(with_trials(INSERTION, trials, work / "insertion.toml"))
    rows: list[Row] = []
    rates: dict[int, list[float]] = {1: [], 2: []}
    dirs: dict[int, Path] = {}
    loads: dict[int, list[str]] = {1: [], 2: []}
    for r in range(rounds):
        for workers in (1, 2):
            steal.fraction()
            results = work / f"insertion_{workers}w_{r}"
            dirs.setdefault(workers, results)        # the first round's results: the same-seeds check
            s: RunSummary = run_campaign(campaign, results, workers=workers)
            rates[workers].append(60.0 * s.ran / s.trials_time)
            loads[workers].append(conditions(steal))
    for workers in (1, 2):
        rows.append((f"insertion trials per minute, {workers} worker(s) ({trials} trials, {rounds} rounds; "
                     f"task {np.median(task_times(dirs[workers])):.2f} s median)",
                     "best {:.1f} /min (rounds {})".format(max(rates[workers]),
                                                          ", ".join(f"{v:.1f}" for v in rates[workers])),
                     "-", "; ".join(loads[workers])))
    eff = max(rates[2]) / (2 * max(rates[1]))
    per_round = ", ".join(f"{100 * b / (2 * a):.0f} %" for a, b in zip(rates[1], rates[2]))
    rows.append(("scaling efficiency 2 workers on 2 cores (best rate2 / (2 best rate1))",
                 f"{100 * eff:.0f} % (per round {per_round})", ">= 80 % on an idle machine", conditions(steal)))
    return rows, dirs


def against(work: Path, other: Path, trials: int, rounds: int, steal: CpuSteal) -> list[Row]:
    """This tree's insertion campaign rate on 2 workers against another checkout's, alternating."""
    python = other / ".venv" / "bin" / "python"
    if not python.exists():
        return [(f"against {other}", f"no {python}: set it up with its ./scripts/run_tests.sh --co -q", "", "")]
    commit = subprocess.run(["git", "-C", str(other), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip() or "?"
    campaign = with_trials(INSERTION, trials, work / "insertion_against.toml")
    trees = {"this tree": (ROOT, Path(sys.executable)), f"{other} ({commit})": (other, python)}
    rates: dict[str, list[float]] = {name: [] for name in trees}
    cpu: dict[str, list[float]] = {name: [] for name in trees}     # s of CPU per trial, whole process tree
    loads: list[str] = []
    for r in range(rounds):
        for name, (root, exe) in trees.items():
            steal.fraction()
            results = work / f"against_{len(rates[name])}_{'this' if root == ROOT else 'other'}"
            used = _children_cpu()
            out = subprocess.run([str(exe), "-m", "spacearm.console.main", "campaign", "run", str(campaign),
                                  "--results", str(results), "--workers", "2", "--json", "--no-report"],
                                 cwd=root, capture_output=True, text=True, timeout=3600)
            if out.returncode != 0:
                return [(f"against {name}", f"campaign failed: {out.stderr.strip()[-120:]}", "", conditions(steal))]
            summary = json.loads(out.stdout)
            rates[name].append(60.0 * summary["ran"] / summary["trials_time"])
            cpu[name].append((_children_cpu() - used) / summary["ran"])
            loads.append(conditions(steal))
    (mine, theirs) = rates.values()
    same = deterministic(work / "against_0_this")
    agree = sum(deterministic(work / "against_0_other").get(k) == v for k, v in same.items())
    tasks = {name: np.median(task_times(work / f"against_0_{tag}")) for name, tag in zip(rates, ("this", "other"))}
    rows: list[Row] = [(f"insertion trials per minute, 2 workers, {name} ({trials} trials, {rounds} rounds; "
                        f"task {tasks[name]:.2f} s median)",
                        "best {:.1f} /min (rounds {})".format(max(v), ", ".join(f"{x:.1f}" for x in v)), "-", "")
                       for name, v in rates.items()]
    per_round = ", ".join(f"{a / b:.2f}x" for a, b in zip(mine, theirs))
    rows.append((f"  this tree / {commit}: best rate over best rate (per round)", f"{max(mine) / max(theirs):.2f}x ({per_round})",
                 ">= 2x the issue-35 tree 9e80b96", "; ".join(loads)))
    (cpu_mine, cpu_theirs) = (float(np.median(v)) for v in cpu.values())
    rows.append((f"  CPU per trial, campaign process tree: this tree / {commit} (median of rounds)",
                 f"{cpu_mine:.2f} / {cpu_theirs:.2f} s = {cpu_theirs / cpu_mine:.2f}x fewer (rounds "
                 + ", ".join(f"{b / a:.2f}x" for a, b in zip(*cpu.values())) + ")",
                 "- (the rate's cost, whatever else shares the cores)", "; ".join(loads)))
    rows.append((f"  same seeds, this tree == {commit} (trials equal)", f"{agree}/{len(same)}", "all", conditions(steal)))
    return rows


def _children_cpu() -> float:
    """CPU of every reaped descendant: the campaign CLI, its Dask nannies and workers, once
    each level has waited for the one below (the cluster's close)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def overhead(work: Path, trials: int, steal: CpuSteal) -> list[Row]:
    campaign = load_campaign(with_trials(EKF, trials, work / "ekf.toml"))
    steal.fraction()
    s = run_campaign(campaign, work / "ekf_overhead", workers=1)
    task = float(np.mean(task_times(work / "ekf_overhead")))
    per_trial = s.trials_time / s.ran - task
    return [(f"scheduler overhead per trial (1 worker, {s.ran} EKF trials of {1e3 * task:.0f} ms)",
             f"{1e3 * per_trial:.1f} ms", "<= 50 ms", conditions(steal))]


def kill_and_resume(work: Path, trials: int, steal: CpuSteal) -> list[Row]:
    """Run `spacearm campaign run` in its own process group, SIGKILL the group at half, resume."""
    campaign = with_trials(EKF, trials, work / "ekf_kill.toml")
    results = work / "ekf_kill"
    cmd = [sys.executable, "-m", "spacearm.console.main", "campaign", "run", str(campaign),
           "--results", str(results), "--workers", "2", "--json", "--no-report"]
    steal.fraction()
    proc = subprocess.Popen(cmd, cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    try:
        while time.monotonic() < deadline and len(ResultStore(results).done_ids()) < trials // 2:
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)      # the process group this benchmark started
        proc.wait(10)
    before = {p.name: p.stat().st_mtime_ns for p in (results / "trials").glob("t*.parquet")}
    out = subprocess.run(cmd + ["--resume"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        return [("kill half-way + resume", f"resume failed: {out.stderr.strip()[:80]}", "0 lost, 0 twice", "")]
    summary = json.loads(out.stdout)
    after = {p.name: p.stat().st_mtime_ns for p in (results / "trials").glob("t*.parquet")}
    lost = trials - len(after)
    twice = sum(after.get(name) != mtime for name, mtime in before.items()) + max(0, summary["ran"] - (trials - len(before)))
    return [(f"campaign killed (SIGKILL) after {len(before)}/{trials} trials, resumed: lost / run twice",
             f"{lost} / {twice}", "0 / 0", conditions(steal))]


def same_seeds(work: Path, dirs: dict[int, Path], skip_netns: bool, steal: CpuSteal) -> list[Row]:
    reference = deterministic(dirs[1])
    rows: list[Row] = [("same seeds: LocalCluster 2 workers == 1 worker (trials equal)",
                        f"{sum(deterministic(dirs[2]).get(k) == v for k, v in reference.items())}/{len(reference)}",
                        "all", conditions(steal))]
    if not skip_netns:
        from hil_tests.netns_cluster import NetnsCluster, NetnsUnavailable
        campaign = load_campaign(work / "insertion.toml")
        try:
            with NetnsCluster(workers=2) as cluster:
                run_campaign(campaign, work / "insertion_netns", scheduler=cluster.address)
            remote = deterministic(work / "insertion_netns")
            rows.append(("same seeds: namespace cluster (scheduler + 2 workers in netns) == local",
                         f"{sum(remote.get(k) == v for k, v in reference.items())}/{len(reference)}", "all",
                         conditions(steal)))
        except NetnsUnavailable as exc:
            rows.append(("same seeds: namespace cluster", f"not run: {exc}", "all", ""))
    ids = sorted(reference)[:3]
    matched = sum(replay(dirs[2], trial).matches for trial in ids)
    rows.append((f"same seeds: replayed alone == stored ({', '.join(ids)})", f"{matched}/{len(ids)}", "all",
                 conditions(steal)))
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=12, help="insertion trials per throughput run")
    parser.add_argument("--rounds", type=int, default=2, help="throughput runs of 1 and 2 workers, in turn")
    parser.add_argument("--cheap-trials", type=int, default=40, help="EKF trials for overhead and kill/resume")
    parser.add_argument("--skip-netns", action="store_true", help="leave out the network-namespace cluster")
    parser.add_argument("--against", type=Path, help="another checkout (with its .venv) to compare rates with")
    parser.add_argument("--only-against", action="store_true", help="the --against rows alone")
    args = parser.parse_args(argv)
    steal = CpuSteal()
    with tempfile.TemporaryDirectory(prefix="bench_campaign_") as tmp:
        work = Path(tmp)
        rows = []
        if not args.only_against:
            rows, dirs = throughput(work, args.trials, args.rounds, steal)
            rows += overhead(work, args.cheap_trials, steal)
            rows += kill_and_resume(work, args.cheap_trials, steal)
            rows += same_seeds(work, dirs, args.skip_netns, steal)
        if args.against:
            rows += against(work, args.against.resolve(), args.trials, args.rounds, steal)
    width = max(len(r[0]) for r in rows)
    print(f"\nbench_campaign on {platform.node()} ({platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores), Python {platform.python_version()}")
    print(f"{'figure':<{width}}  {'measured':<44}  {'target':<28}  machine")
    for name, value, target, machine in rows:
        print(f"{name:<{width}}  {value:<44}  {target:<28}  {machine}")


if __name__ == "__main__":
    main()
