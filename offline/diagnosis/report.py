"""Diagnosis output: Markdown report with PNG plots, JSON summary, updated plant TOML."""
from __future__ import annotations

import json
from pathlib import Path

import tomli_w

from spacearm.offline.diagnosis.analysis import Diagnosis
from spacearm.offline.diagnosis.joint_units import parameter_units, units_of
from spacearm.firmware_sim.plant import PlantConfig


def summary(d: Diagnosis) -> dict:
    kinds = joint_kinds(d)
    return {
        "verdict": d.verdict,
        "significant": bool(d.findings or d.unexplained or d.sensor_findings),
        "unexplained_channels": [c.name for c in d.unexplained],
        "heldout_from_s": d.heldout_start,
        "not_reported": d.not_reported,
        "model_wrong": d.model_wrong,
        "time_base_repairs": d.repairs,
        "joints": [{"joint": j + 1, "kind": kind, "position_unit": units_of(kind).position,
                    "effort_unit": units_of(kind).effort} for j, kind in enumerate(kinds)],
        "sensor_findings": [{"effect": f.effect, "channel": f.channel, "joint": f.joint + 1, "parameters": f.params,
                             "kind": kinds[f.joint], "unit": _sensor_unit(f.effect, kinds[f.joint]),
                             "text": f.text} for f in d.sensor_findings],
        "findings": [{
            "rank": i + 1, "effects": list(f.fit.effects), "channel": f.fit.channel,
            "joint": f.fit.index + 1 if f.fit.channel != "wrench" else None,
            "axis": f.fit.index if f.fit.channel == "wrench" else None,
            **_units(f, kinds),
            "parameters": f.params, "stderr": f.stderr, "text": f.text, "score": f.score,
            "p_value": f.fit.p_value, "heldout_rms_reduction_residual_model": f.fit.heldout_reduction,
            "change_point_s": f.onset, "equally_good": f.alternatives} for i, f in enumerate(d.findings)],
        "channels": [{"name": c.name, "unit": _channel_unit(c.name, kinds), "noise": c.noise,
                      "heldout_rms_before": c.rms_before,
                      "heldout_rms_after": c.rms_after, "significant": c.significant, "metric": c.metric,
                      "mismatch_before": c.excess_before, "mismatch_after": c.excess_after,
                      "unexplained_from_s": c.onset} for c in d.channels],
        "timings_s": d.timings,
    }


def joint_kinds(d: Diagnosis) -> list[str]:
    """Each recorded joint's kind, from the plant the diagnosis replayed."""
    n = sum(1 for c in d.channels if c.name.startswith("q_"))
    return [d.updated.joint_params(j).kind for j in range(n)]


def _units(f, kinds: list[str]) -> dict:
    """A finding's joint kind and its parameters' units (F/T axes: N or N m)."""
    if f.fit.channel == "wrench":
        unit = "N" if f.fit.index < 3 else "N m"
        return {"kind": None, "unit": {"bias": unit, "drift": f"{unit}/s"}}
    kind = kinds[f.fit.index]
    table = parameter_units(kind)
    return {"kind": kind, "unit": {k: table[k] for k in f.params if k in table}}


def _sensor_unit(effect: str, kind: str) -> str:
    u = units_of(kind)
    return {"position_quantisation": u.position, "torque_quantisation": u.effort}.get(effect, "s")


def _channel_unit(name: str, kinds: list[str]) -> str:
    if name.startswith(("q_", "tau_")):
        u = units_of(kinds[int(name.split("_")[1]) - 1])
        return u.position if name.startswith("q_") else u.effort
    return "N" if name.startswith("f") else "N m"


def write_plant(path: Path, config: PlantConfig, note: str) -> None:
    data = config.model_dump(mode="json", exclude_none=True, exclude_defaults=True)
    text = "".join(f"# {line}\n" for line in note.splitlines()) + tomli_w.dumps(data)
    Path(path).write_text(text)


def write_report(d: Diagnosis, out: Path, source: str, nominal: PlantConfig) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    data = summary(d)
    (out / "summary.json").write_text(json.dumps(data, indent=2))
    write_plant(out / "plant_fitted.toml", d.updated,
                f"Nominal plant with the effects fitted by `spacearm diagnose {source}`:\n{d.verdict}")
    lines = [f"# Sim-vs-real diagnosis of `{source}`", "", f"**{d.verdict}**", "",
             f"Held-out part: t >= {d.heldout_start:.1f} s (fits use the rows before it).", ""]
    if d.findings:
        lines += ["| rank | finding | p-value | score (explained / noise variance) | change point s |",
                  "| --- | --- | --- | --- | --- |"]
        for i, f in enumerate(d.findings):
            onset = f"{f.onset:.1f}" if f.onset is not None else "-"
            alts = "".join(f"; or equally well: {a}" for a in f.alternatives)
            lines.append(f"| {i + 1} | {f.text}{alts} | {f.fit.p_value:.1e} | {f.score:.1f} | {onset} |")
        lines += ["", "Updated plant file: `plant_fitted.toml`.", ""]
    if d.sensor_findings:
        lines += ["Sensor effects (read from the recording, not part of the re-simulation):", ""] + \
            [f"- {f.text}" for f in d.sensor_findings] + [""]
    if d.not_reported:
        lines += ["Fitted but not reported:", ""] + [f"- {w}" for w in d.not_reported] + [""]
    if d.repairs:
        lines += ["Time base (how the recording was put on one period before the replay):", ""] + \
            [f"- {w}" for w in d.repairs] + [""]
    lines += ["Mismatch statistic: residual vs noise as a multiple of the significance limit (> 1: significant).",
              "", "| channel | noise | held-out RMS before | after | reduction | mismatch before | after |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for c in d.channels:
        red = 1.0 - c.rms_after / c.rms_before if c.rms_before > 0 else 0.0
        mark = " **" if c.significant else ""
        lines.append(f"| {c.name}{mark} | {c.noise:.3g} | {c.rms_before:.3g} | {c.rms_after:.3g} | {100 * red:.0f} % "
                     f"| {c.excess_before:.2f} | {c.excess_after:.2f} |")
    for i, f in enumerate(d.findings[:4]):
        name = f"tau_{f.fit.index + 1}" if f.fit.channel == "tau" else (
            f"q_{f.fit.index + 1}" if f.fit.channel == "q" else ["fx", "fy", "fz", "tx", "ty", "tz"][f.fit.index])
        fig, (a, b) = plt.subplots(1, 2, figsize=(11, 3.5))
        a.plot(d.t, d.residual_before[name], lw=0.5, label="recording - nominal sim")
        a.plot(d.t, d.residual_after[name], lw=0.5, label="recording - fitted sim")
        a.axvline(d.heldout_start, color="k", ls="--", lw=0.8)
        a.set_xlabel("t s"), a.set_ylabel(f"{name} residual"), a.legend(fontsize=7)
        cond = f.fit.prediction
        b.plot(cond, d.residual_before[name], ".", ms=1)
        b.set_xlabel(f"predicted by {'+'.join(f.fit.effects)}"), b.set_ylabel("residual")
        fig.tight_layout()
        png = f"finding_{i + 1}_{name}.png"
        fig.savefig(out / png, dpi=90)
        plt.close(fig)
        lines += ["", f"![{f.text}]({png})"]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return data
