"""Monte-Carlo study drivers: run, aggregate, and format tables beside the papers' numbers.

Each function returns the printable text plus a dict of the measured headline numbers, so the
console, the benchmark and tests share them.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from spacearm.controller.calibration import study_ekf as E
from spacearm.controller.calibration import study_laser as L
from spacearm.controller.calibration.plots import box_panels, error_vs_configs
from spacearm.controller.calibration.validation import mean_stats


# ------------------------------------------------------------------------------- laser ranger
def laser_study(runs: int = 20, seed0: int = 0, cases=(50, 100), n_random: int = 10_000,
                progress=None) -> tuple[str, dict]:
    t0 = time.perf_counter()
    st = L.setup()
    lines = ["Laser-ranger identification study (Table 1 arm, Table 2 errors, plane y + 4.6 z - 0.69 = 0,",
             "  error 0.005 on 4.6; noise 0.2 mm, 10 repetitions; 101 candidates; 20 validation postures)",
             "", st.report.summary(), ""]
    # Noise-free check: the identification must return the Table 2 errors exactly.
    _, clean = L.run_once(st, seed0, cases=(max(cases),), noise=0.0, methods=("lm",))
    est = clean[0].fits["lm"].estimate
    worst = max(abs(est[n] - st.errors.get(n, 0.0)) for n in est)
    lines.append(f"noise-free recovery: max |identified - true| over {len(est)} parameters = {worst:.2e} (SI)")
    nominal, per_case = [], {m: {"lm": [], "lse": []} for m in cases}
    o3 = {m: [] for m in cases}
    for k in range(runs):
        nom, rr = L.run_once(st, seed0 + k, cases=cases)
        nominal.append(nom)
        for r in rr:
            o3[r.m].append(r.O3)
            for meth, s in r.stats.items():
                per_case[r.m][meth].append(s)
        if progress:
            progress(k + 1, runs)
    blocks = {"nominal": mean_stats(nominal)}
    for m in cases:
        for meth in ("lm", "lse"):
            blocks[f"{m}/{meth}"] = mean_stats(per_case[m][meth])
    lines += ["", f"Validation errors, mean over {runs} Monte-Carlo runs (ours) | paper Table 5",
              f"{'case':<12}{'ax':<3}{'RMS pos mm':>22}{'RMS ori mrad':>22}{'max pos mm':>22}{'max ori mrad':>22}"]
    for key, b in blocks.items():
        paper_key = "nominal" if key == "nominal" else key.split("/")[0]
        paper = L.PAPER_TABLE5.get(paper_key)
        label = key if key == "nominal" else f"{key.split('/')[0]} cfg {key.split('/')[1].upper()}"
        for ax in range(3):
            cells = []
            for col in ("rms_pos", "rms_rot", "max_pos", "max_rot"):
                ours = b[col][ax] * 1e3
                p = paper[col][ax] if paper else float("nan")
                cells.append(f"{ours:9.4f} | {p:8.4f}")
            lines.append(f"{label if ax == 0 else '':<12}{'xyz'[ax]:<3}" + "".join(f"{c:>22}" for c in cells))
    lines.append("")
    lines.append("O3 of the selected sets (mean): " + ", ".join(
        f"{m} configs {np.mean(o3[m]):.3f}" for m in cases) + "  (paper: 0.048 / 0.180, its own units)")
    bench = [L.selection_benchmark(st, m, seed=seed0, n_random=n_random) for m in cases]
    for b in bench:
        lines.append(f"selection m={b['m']}: greedy+exchange O3 {b['selected_O3']:.4f} in {b['seconds']:.2f} s "
                     f"({b['sweeps']} sweeps); best of {n_random} random subsets {b['random_best_O3']:.4f} "
                     f"(median {b['random_median_O3']:.4f}); ratio {b['ratio']:.3f}")
        lines.append("    indices of the selected set: " + ", ".join(f"{k} {v:.4g}" for k, v in b["indices"].items()))
    headline = {
        "noise_free_max_error": worst,
        "rms_pos_mm": {m: (blocks[f"{m}/lm"]["rms_pos"] * 1e3).tolist() for m in cases},
        "max_pos_mm": {m: (blocks[f"{m}/lm"]["max_pos"] * 1e3).tolist() for m in cases},
        "rms_rot_mrad": {m: (blocks[f"{m}/lm"]["rms_rot"] * 1e3).tolist() for m in cases},
        "selection": bench, "seconds": time.perf_counter() - t0}
    lines.append(f"({runs} runs in {headline['seconds']:.1f} s)")
    return "\n".join(lines), headline


# ------------------------------------------------------------------------------------ EKF
METHOD_LABEL = {"lse": "LSE", "ekf": "EKF (paper P0,Q,R)", "ekf_cov": "EKF (cov-tuned)",
                "lm": "LM full-cov MAP", "ekf_default": "EKF (default tuning)"}


def ekf_study(runs: int = 10, seed0: int = 0, out_dir: Path | None = None,
              counts=(10, 20, 40, 60, 80, 100, 150, 200), count_reps: int = 10,
              progress=None) -> tuple[str, dict]:
    t0 = time.perf_counter()
    st = E.setup()
    methods = ("lse", "ekf", "ekf_default", "ekf_cov", "lm")
    lines = ["EKF vision calibration study (7-DOF SSRMS-type arm, Table 3 errors, control noise 0.01 deg,",
             f"  50 identification / 200 validation postures, {runs} Monte-Carlo runs)", ""]
    # ---- Table 4 at 0.3 mm / 0.5 deg
    runs_main = [E.run_once(st, seed0 + k, methods=methods) for k in range(runs)]
    if progress:
        progress("table 4")
    keys = ("initial", *methods, "floor")
    t4 = {k: {kk: np.mean([r.stats[k].table4()[kk] for r in runs_main])
              for kk in runs_main[0].stats[k].table4()} for k in keys}
    lines += ["Table 4 (0.3 mm / 0.5 deg): ours (mean over runs) | paper; position mm, orientation deg",
              f"{'method':<22}" + "".join(f"{h:>22}" for h in ("pos avg", "pos extreme", "X avg", "Y avg", "Z avg", "X extreme"))]
    paper_map = {"initial": "initial", "lse": "lse", "ekf": "ekf"}
    for k in keys:
        p = E.PAPER_TABLE4.get(paper_map.get(k, ""), None)
        d = t4[k]

        def cell(v, pv):
            return f"{v:9.4f} | {pv:8.4f}" if pv is not None else f"{v:9.4f} |     -   "
        lab = {"initial": "initial (nominal)", "floor": "floor (true params)"}.get(k, METHOD_LABEL.get(k, k))
        lines.append(
            f"{lab:<22}{cell(d['pos_mean'] * 1e3, p['pos'][1] if p else None):>22}"
            f"{cell(d['pos_max'] * 1e3, p['pos'][0] if p else None):>22}"
            f"{cell(np.degrees(d['rotx_mean']), p['rotx'][1] if p else None):>22}"
            f"{cell(np.degrees(d['roty_mean']), p['roty'][1] if p else None):>22}"
            f"{cell(np.degrees(d['rotz_mean']), p['rotz'][1] if p else None):>22}"
            f"{cell(np.degrees(d['rotx_max']), p['rotx'][0] if p else None):>22}")
    floor = t4["floor"]["pos_mean"]
    ratios = {k: t4[k]["pos_mean"] / floor for k in methods}
    lines.append("ratio to floor (mean position error): " + ", ".join(
        f"{METHOD_LABEL[k]} {v:.3f}" for k, v in ratios.items())
        + "   (paper: EKF 2.3335/~1.94 = 1.2, LSE 5.26/1.94 = 2.7)")
    times = {k: float(np.mean([r.fits[k].elapsed for r in runs_main])) for k in methods}
    lines.append("identification time (28 parameters, 50 postures): " + ", ".join(
        f"{METHOD_LABEL[k]} {v * 1e3:.1f} ms" for k, v in times.items()))
    # ---- Table 5: four noise levels
    lines += ["", "Table 5: mean position error after calibration, ours (avg / extremum) | paper (avg / extremum), mm",
              f"{'method':<22}" + "".join(f"{f'{sp * 1e3:g} mm/{np.degrees(sr):g} deg':>30}" for sp, sr in E.NOISE_LEVELS)]
    t5: dict[str, list] = {k: [] for k in (*methods, "floor")}
    by_level = []
    for sp, sr in E.NOISE_LEVELS:
        rs = [E.run_once(st, seed0 + k, sigma_p=sp, sigma_r=sr, methods=methods) for k in range(runs)]
        by_level.append(rs)
        for k in t5:
            t5[k].append((np.mean([r.stats[k].pos_norm.mean() for r in rs]) * 1e3,
                          np.mean([r.stats[k].pos_norm.max() for r in rs]) * 1e3))
    if progress:
        progress("table 5")
    for k, vals in t5.items():
        pap = E.PAPER_TABLE5.get(k)
        cells = []
        for i, (a, e) in enumerate(vals):
            pa = f"{pap[i][0]:.3f}/{pap[i][1]:.3f}" if pap else "-"
            cells.append(f"{a:.3f}/{e:.3f} | {pa}")
        lab = "floor (true params)" if k == "floor" else METHOD_LABEL[k]
        lines.append(f"{lab:<22}" + "".join(f"{c:>30}" for c in cells))
    # ---- Figure 8: error vs number of configurations
    curves = {k: ([], []) for k in ("lse", "ekf", "lm")}
    floors = []
    Qv = E.nonsingular_configurations(st, 200, np.random.default_rng(10_000 + seed0))
    for n in counts:
        rs = [E.run_once(st, 1000 * n + seed0 + k, n_ident=n, methods=("lse", "ekf", "lm"), Qv=Qv)
              for k in range(count_reps)]
        floors.append(np.mean([r.stats["floor"].pos_norm.mean() for r in rs]) * 1e3)
        for k in curves:
            v = np.array([r.stats[k].pos_norm.mean() for r in rs]) * 1e3
            curves[k][0].append(v.mean())
            curves[k][1].append(v.std())
    if progress:
        progress("figure 8")
    lines += ["", f"Figure 8: mean validation position error (mm) vs identification configurations ({count_reps} runs each)",
              f"{'configs':<10}" + "".join(f"{METHOD_LABEL[k]:>22}" for k in curves) + f"{'floor':>10}"]
    for i, n in enumerate(counts):
        lines.append(f"{n:<10}" + "".join(f"{curves[k][0][i]:>22.3f}" for k in curves) + f"{floors[i]:>10.3f}")
    files = []
    if out_dir is not None:
        out_dir = Path(out_dir)
        f7 = {"position": {}, "X orientation": {}, "Y orientation": {}, "Z orientation": {}}
        for k in ("initial", *methods, "floor"):
            lab = METHOD_LABEL.get(k, k)
            f7["position"][lab] = np.concatenate([r.stats[k].pos_norm for r in runs_main]) * 1e3
            for i, ax in enumerate("XYZ"):
                f7[f"{ax} orientation"][lab] = np.degrees(np.abs(np.concatenate([r.stats[k].rot[:, i] for r in runs_main])))
        units = {"position": "mm", "X orientation": "deg", "Y orientation": "deg", "Z orientation": "deg"}
        files.append(box_panels(out_dir / "ekf_fig7_boxplots.png", f7,
                                "Validation errors at 0.3 mm / 0.5 deg (cf. EKF paper Fig. 7)", units))
        f9 = {"position": {}, "X orientation": {}, "Y orientation": {}, "Z orientation": {}}
        for (sp, sr), rs in zip(E.NOISE_LEVELS, by_level):
            for k in ("lse", "ekf", "lm"):
                lab = f"{k.upper()} {sp * 1e3:g}/{np.degrees(sr):g}"
                f9["position"][lab] = np.concatenate([r.stats[k].pos_norm for r in rs]) * 1e3
                for i, ax in enumerate("XYZ"):
                    f9[f"{ax} orientation"][lab] = np.degrees(np.abs(np.concatenate([r.stats[k].rot[:, i] for r in rs])))
        files.append(box_panels(out_dir / "ekf_fig9_noise_levels.png", f9,
                                "Validation errors per noise level (mm / deg) (cf. EKF paper Fig. 9)", units))
        files.append(error_vs_configs(out_dir / "ekf_fig8_configs.png", list(counts),
                                      {METHOD_LABEL[k]: (np.array(v[0]), np.array(v[1])) for k, v in curves.items()},
                                      float(np.mean(floors)), "Error vs number of configurations (cf. Fig. 8)"))
        lines += [""] + [f"wrote {f}" for f in files]
    head = {"floor_mm": floor * 1e3, "ratios": ratios, "times_s": times,
            "table4": {k: {kk: float(v) for kk, v in d.items()} for k, d in t4.items()},
            "seconds": time.perf_counter() - t0}
    lines.append(f"(study took {head['seconds']:.1f} s)")
    return "\n".join(lines), head
