"""Which D-H groups and joint compliances to fit, chosen by leave-one-posture-out error on the
training postures only.

With few postures per parameter (TIAGo motion capture: 37 postures, 31 terms), a D-H group the
data determine poorly (there the common-normal lengths a_i) adds more estimation noise to a new
posture's prediction than the geometric error it removes. Backward selection: drop the group
whose removal lowers the leave-one-out error on the training postures most (trusted_fit's
loo_position_rms), and repeat while that lowers it by more than `MIN_GAIN`. A joint compliance
k_j is a group of its own: one physical hypothesis (this drive gives under its load), which the
same criterion keeps or drops, so that a compliance the data only fit to noise does not stay
because its deflection bound made it detectable. The measurement set-up's unknowns
(registration, marker, anchor, plane) are never dropped. Held-out or validation postures take no
part in the choice, so their figure stays an honest estimate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from spacearm.controller.calibration.errormodel import COMPLIANCE, DH_KINDS

MIN_GAIN = 0.02          # a drop must lower the leave-one-out RMS by 2 %: parsimony on a close call


@dataclass(frozen=True)
class GroupSelection:
    kept: list[str]                          # candidate names left
    dropped: tuple[str, ...]                 # D-H groups ("a") and compliances ("k_7") dropped, in order
    steps: tuple[tuple[str, float], ...]     # ("all" or "-GROUP", leave-one-out RMS in m) per accepted step

    def summary(self) -> str:
        path = " -> ".join(f"{what} {err * 1e3:.3f} mm" for what, err in self.steps)
        dropped = ", ".join(_label(g) for g in self.dropped) or "none"
        return f"D-H groups and compliances by leave-one-out on the training postures: {path}; dropped {dropped}"


def dh_group(name: str) -> str | None:
    """The selectable group of a candidate: its D-H kind ("a"), a compliance's own name ("k_7"),
    or None for the set-up's unknowns."""
    head, _, tail = name.rpartition("_")
    if not tail.isdigit():
        return None
    if head == COMPLIANCE:
        return name
    return head if head in DH_KINDS else None


def _label(group: str) -> str:
    return group if group.startswith(COMPLIANCE + "_") else f"{group}_i"


def select_groups(candidates: list[str], cv_error: Callable[[list[str]], float],
                  min_gain: float = MIN_GAIN) -> GroupSelection:
    """Backward selection of D-H groups and compliances; `cv_error(names)` is the leave-one-out RMS (m) of a fit of
    these candidates on the training postures (inf: cannot be fitted)."""
    current = list(candidates)
    best = cv_error(current)
    steps, dropped = [("all", best)], []
    while True:
        trials = {}
        for group in sorted({dh_group(n) for n in current} - {None}):
            trials[group] = cv_error([n for n in current if dh_group(n) != group])
        if not trials:
            break
        group, err = min(trials.items(), key=lambda kv: kv[1])
        if not math.isfinite(err) or err > best * (1.0 - min_gain):     # inf: too few postures to tell
            break
        current = [n for n in current if dh_group(n) != group]
        best = err
        dropped.append(group)
        steps.append((f"-{_label(group)}", err))
    return GroupSelection(current, tuple(dropped), tuple(steps))
