"""PNG figures of the studies (matplotlib, headless): box plots like the EKF paper's Figs. 7 and 9,
and error against number of configurations like its Fig. 8."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def box_panels(path: Path, panels: dict[str, dict[str, np.ndarray]], title: str,
               units: dict[str, str]) -> Path:
    """One subplot per panel (e.g. position, X/Y/Z orientation); one box per method."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.0))
    axes = np.atleast_1d(axes)
    for ax, (name, groups) in zip(axes, panels.items()):
        ax.boxplot(list(groups.values()), tick_labels=list(groups.keys()), showfliers=True)
        ax.set_title(name)
        ax.set_ylabel(units.get(name, ""))
        meds = [np.median(v) for v in groups.values() if len(v)]
        if meds and min(meds) > 0 and max(meds) / min(meds) > 20:
            ax.set_yscale("log")    # before/after differ by orders of magnitude
        ax.tick_params(axis="x", rotation=30)
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def error_vs_configs(path: Path, counts: list[int], curves: dict[str, tuple[np.ndarray, np.ndarray]],
                     floor: float, title: str) -> Path:
    """Mean (left) and standard deviation (right) of validation position error vs configurations."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    for name, (mean, std) in curves.items():
        a1.plot(counts, mean, marker="o", label=name)
        a2.plot(counts, std, marker="o", label=name)
    a1.axhline(floor, color="k", ls="--", label="floor (true parameters)")
    a1.set_xlabel("identification configurations")
    a1.set_ylabel("mean position error / mm")
    a2.set_xlabel("identification configurations")
    a2.set_ylabel("std of mean position error over runs / mm")
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.legend()
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
