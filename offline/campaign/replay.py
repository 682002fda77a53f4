"""Replay one trial of a result directory alone, in this process, and compare with what was stored.

The trial's seed is in its row; its parameters are drawn again from that seed and must equal the
stored ones (the campaign file is in the directory's manifest), then the trial runs and every
deterministic figure is compared. Wall-clock timings are never compared.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from spacearm.offline.campaign.kinds import KINDS
from spacearm.offline.campaign.runner import execute_trial, make_task
from spacearm.offline.campaign.store import ResultStore, code_version

@dataclass
class FigureCheck:
    name: str
    stored: float
    replayed: float
    atol: float = 0.0      # the kind's replay tolerance (0: equal to rounding, a pure function of the seed)

    @property
    def equal(self) -> bool:
        if math.isnan(self.stored) and math.isnan(self.replayed):
            return True
        return math.isclose(self.stored, self.replayed, rel_tol=1e-9, abs_tol=max(self.atol, 1e-15))


@dataclass
class ReplayResult:
    trial_id: str
    seed: int
    stored_version: str
    replay_version: str
    parameters_equal: bool
    success_stored: bool
    success_replayed: bool
    figures: list[FigureCheck] = field(default_factory=list)
    differing: list[str] = field(default_factory=list)   # series and labels that differ

    @property
    def matches(self) -> bool:
        return (self.parameters_equal and self.success_stored == self.success_replayed
                and all(f.equal for f in self.figures) and not self.differing)


def replay(results: str | Path, trial: str) -> ReplayResult:
    store = ResultStore(results)
    campaign = store.campaign()
    row = store.row(trial)
    task = make_task(campaign, int(row["index"]))
    stored_params = {k[2:]: v for k, v in row.items() if k.startswith("p_") and v is not None}
    params_equal = task.seed == row["seed"] and task.parameters == stored_params
    out = execute_trial(task)
    stored_figures = {k[2:]: v for k, v in row.items() if k.startswith("f_") and v is not None}
    names = sorted(set(stored_figures) | set(out["figures"]))
    atol = KINDS[task.kind].replay_atol
    checks = [FigureCheck(n, float(stored_figures.get(n, math.nan)), float(out["figures"].get(n, math.nan)),
                          atol.get(n, 0.0)) for n in names]
    return ReplayResult(trial, int(row["seed"]), row["code_version"], code_version(), params_equal,
                        bool(row["success"]), out["success"], checks, _differing(row, out, atol))


def _differing(row: dict, out: dict, atol: dict[str, float]) -> list[str]:
    """Series (to rounding, or the kind's tolerance) and labels (exactly) that differ."""
    bad = []
    stored = {k[2:]: v for k, v in row.items() if k.startswith("s_") and v is not None}
    for name in sorted(set(stored) | set(out.get("series", {}))):
        a, b = stored.get(name), out.get("series", {}).get(name)
        if a is None or b is None or len(a) != len(b) or not all(
                FigureCheck(name, x, y, atol.get(name, 0.0)).equal for x, y in zip(a, b)):
            bad.append(name)
    labels = {k[2:]: v for k, v in row.items() if k.startswith("l_") and v is not None}
    bad += [k for k in sorted(set(labels) | set(out.get("labels", {}))) if labels.get(k) != out.get("labels", {}).get(k)]
    return bad
