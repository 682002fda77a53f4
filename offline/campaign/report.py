"""The campaign's report: summary table, success rate with its Wilson interval, distributions of
the figures and the worst trials, as Markdown + PNG in RESULTS/report/."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacearm.offline.campaign.figure_units import figure_unit
from spacearm.offline.campaign.kinds import KINDS
from spacearm.offline.campaign.store import ResultStore

Z95 = 1.959963984540054


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default); (0, 1) when n = 0."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass
class FigureSummary:
    name: str
    count: int
    median: float
    p95: float
    maximum: float


@dataclass
class CampaignSummary:
    name: str
    kind: str
    code_version: str
    campaign_hash: str
    trials: int            # planned
    finished: int
    successes: int
    failed: int
    errors: int
    interval: tuple[float, float]
    figures: list[FigureSummary]
    worst: list[dict[str, Any]]
    worst_figure: str

    @property
    def success_rate(self) -> float:
        n = self.finished - self.errors
        return self.successes / n if n else math.nan

    def rate_text(self) -> str:
        """'97.0 % (95 % CI 91.5 - 99.0 %)', or '-' with no valid trial."""
        if math.isnan(self.success_rate):
            return "- (no trial finished without raising)"
        lo, hi = self.interval
        return f"{100 * self.success_rate:.1f} % (95 % CI {100 * lo:.1f} - {100 * hi:.1f} %)"


def summarise(store: ResultStore, worst_count: int = 5) -> CampaignSummary:
    manifest = store.manifest()
    rows = store.rows()
    valid = [r for r in rows if r.get("error") is None]
    successes = sum(bool(r["success"]) for r in valid)
    figure_names = sorted({k for r in valid for k, v in r.items() if k.startswith("f_") and v is not None})
    figures = []
    for name in figure_names:
        values = np.array([r[name] for r in valid if r.get(name) is not None], dtype=float)
        values = values[np.isfinite(values)]
        if values.size:
            figures.append(FigureSummary(name[2:], int(values.size), float(np.median(values)),
                                         float(np.percentile(values, 95)), float(values.max())))
    worst_figure = KINDS[manifest["kind"]].worst if manifest["kind"] in KINDS else ""
    key = f"f_{worst_figure}"
    # the worst: failed and broken trials first, then the largest worst-figure values
    ranked = sorted(rows, key=lambda r: (r.get("error") is None and bool(r["success"]),
                                         -(r.get(key) if r.get(key) is not None else -math.inf)))
    return CampaignSummary(manifest["name"], manifest["kind"], manifest["code_version"],
                           manifest["campaign_hash"], int(manifest["trials"]), len(rows), successes,
                           len(valid) - successes, len(rows) - len(valid), wilson_interval(successes, len(valid)),
                           figures, ranked[:worst_count], worst_figure)


def write_report(store: ResultStore, out: Path | None = None) -> Path:
    """RESULTS/report/report.md plus success.png and one histogram per figure; returns the .md path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = out or store.root / "report"
    out.mkdir(parents=True, exist_ok=True)
    s = summarise(store)
    rows = [r for r in store.rows() if r.get("error") is None]
    rate = s.success_rate
    lo, hi = s.interval

    fig, ax = plt.subplots(figsize=(4, 3.2))
    if s.finished - s.errors:
        ax.bar([0], [100 * rate], color="tab:green", width=0.5)
        ax.errorbar([0], [100 * rate], yerr=[[100 * (rate - lo)], [100 * (hi - rate)]], color="k", capsize=8)
    ax.set_xticks([0], [f"{s.successes}/{s.finished - s.errors} trials"])
    ax.set_ylim(0, 105)
    ax.set_ylabel("success rate, % (95 % Wilson interval)")
    ax.set_title(s.name)
    fig.tight_layout()
    fig.savefig(out / "success.png", dpi=100)
    plt.close(fig)

    images = []
    for f in s.figures:
        values = np.array([r[f"f_{f.name}"] for r in rows if r.get(f"f_{f.name}") is not None], dtype=float)
        ok = np.array([bool(r["success"]) for r in rows if r.get(f"f_{f.name}") is not None])
        fig, ax = plt.subplots(figsize=(4.5, 3))
        bins = min(30, max(5, int(math.sqrt(values.size)) + 1))
        ax.hist([values[ok], values[~ok]], bins=bins, stacked=True, color=["tab:blue", "tab:red"],
                label=["succeeded", "failed"])
        ax.set_xlabel(f"{f.name} (SI)")
        ax.set_ylabel("trials")
        ax.legend(fontsize=7)
        fig.tight_layout()
        name = f"dist_{f.name}.png"
        fig.savefig(out / name, dpi=90)
        plt.close(fig)
        images.append(name)

    worst_png = _worst_plot(s, out / "worst.png", plt)
    md = [f"# Campaign {s.name} ({s.kind})", "",
          f"code version `{s.code_version}`, campaign file hash `{s.campaign_hash}`", "",
          "| figure | value |", "| --- | --- |",
          f"| trials planned / finished | {s.trials} / {s.finished} |",
          f"| succeeded / failed / broken (raised) | {s.successes} / {s.failed} / {s.errors} |",
          f"| success rate (95 % Wilson interval) | {s.rate_text()} |", "",
          "![success rate](success.png)", "", "## Figures", "",
          "| figure | unit | n | median | p95 | max |", "| --- | --- | --- | --- | --- | --- |"]
    for f in s.figures:          # stored in SI, shown in the unit people read (mm, deg, N, s)
        unit, k = figure_unit(f.name)
        md.append(f"| {f.name} | {unit} | {f.count} | {k * f.median:.4g} | {k * f.p95:.4g} | {k * f.maximum:.4g} |")
    md += [""] + [f"![{i}]({i})" for i in images]
    md += ["", f"## Worst trials (failed first, then largest {s.worst_figure})", "",
           "| trial | seed | success | failure / error | parameters | "
           f"{s.worst_figure} ({figure_unit(s.worst_figure)[0]}) |", "| --- | --- | --- | --- | --- | --- |"]
    for r in s.worst:
        params = ", ".join(f"{k[2:]}={v:.4g}" for k, v in r.items() if k.startswith("p_") and v is not None)
        why = r.get("error") or r.get("failure") or ""
        value = r.get(f"f_{s.worst_figure}")
        value = None if value is None else figure_unit(s.worst_figure)[1] * value
        md.append(f"| {r['trial_id']} | {r['seed']} | {bool(r['success'])} | {why} | {params} | "
                  f"{'' if value is None else f'{value:.4g}'} |")
    if worst_png:
        md += ["", "![worst trials](worst.png)"]
    md += ["", "Replay one trial alone: `spacearm campaign replay RESULTS TRIAL_ID`."]
    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    return path


def _worst_plot(s: CampaignSummary, path: Path, plt) -> bool:
    """The worst trials' worst figure as bars, red where the trial failed; False if none has it."""
    key = f"f_{s.worst_figure}"
    rows = [r for r in s.worst if r.get(key) is not None]
    if not rows:
        return False
    fig, ax = plt.subplots(figsize=(5, 0.4 * len(rows) + 1.2))
    ax.barh([r["trial_id"] for r in rows][::-1], [r[key] for r in rows][::-1],
            color=["tab:blue" if r["success"] else "tab:red" for r in rows][::-1])
    ax.set_xlabel(f"{s.worst_figure} (SI); red: failed")
    ax.set_title("worst trials")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True
