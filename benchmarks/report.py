"""Write docs/benchmarks.md from the benchmark results in benchmarks/results/*.json.

Run: ``python benchmarks/report.py [--results benchmarks/results] [--out docs/benchmarks.md] [--drop-missing]``,
after any of the benchmark scripts (each writes its results file, with the machine and versions it ran on). A
section is regenerated from its results file alone: edit the scripts or rerun them, never the page. Results
files are not kept in the repository, so a section whose file is absent here is kept as the page has it
(``--drop-missing``: removed).
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
HEADER = """# Benchmarks

This page is written by `python benchmarks/report.py` from the results files the benchmark scripts leave in
`benchmarks/results/`; rerun a script, then the report, to refresh it. Times are wall-clock seconds on the
machine named in each row, after compilation unless a row says otherwise. A section whose results file is not
on the machine that writes the page is kept as it was.

| script | what it measures |
|---|---|
| `benchmarks/simulate.py` | one 10 s simulation and one forward-mode gradient of the log-likelihood |
| `benchmarks/sweep.py` | a 500-set Latin-hypercube sweep, the whole `growjax sweep` process, a SciPy BDF baseline |
| `benchmarks/sweep_resume.py` | a `growjax sweep` stopped by SIGINT at about half its chunks and resumed, against the same sweep uninterrupted: tables and time |
| `benchmarks/agreement.py` | fast against reference configuration across the parameter box, both growth laws, six inputs |
| `benchmarks/calibrate.py` | fit, Laplace approximation and NUTS |
| `benchmarks/discover.py` | the discovery matrix: hidden effects, seeds and verdicts |
| `benchmarks/control.py` | control designs evaluated on the reference configuration |
| `benchmarks/windows_public.py` | Y on disjoint windows of the public experiment under each likelihood |
| `benchmarks/coverage_discrepancy.py` | coverage of the fit's intervals on reference-made data with a discrepancy; `coverage_discrepancy_default_budget`: `--groups smooth correlated --budget default` (the rig nominal, fitted as `growjax fit` fits it, with the default budget); `..._once`: the same with `--no-relinearise`; `coverage_discrepancy_tangents`: `--groups smooth correlated rig --budget default --rig-tangents` (the rig's errors as parameters of the model) |
| `benchmarks/predict_public.py` | prediction of a held-out window of the public experiment from a posterior |
| `benchmarks/fit_speed.py` | the fit's cost under the discrepancy likelihood against independent noise, with the rig inferred against it fixed, and the rig's tangents (the default) against its secants, relinearised and linearised once |
| `benchmarks/rig_agreement.py` | Y's interval from the fit (rig inferred; rig fixed) beside the posterior's, coverage and the posterior's band, rig nominal and drawn |
| `benchmarks/set_speed.py` | a joint fit of eight experiments against one experiment's fit |
| `benchmarks/sets.py` | joint fits of sets of four experiments on one drawn rig: coverage, against each experiment alone and against rig errors taken per experiment; `sets_relinearised_singles`: `--relinearise-singles --joint-from sets.json` (the same sets, each experiment alone fitted with the rig relinearised) |
| `benchmarks/mixed_set.py` | a forward experiment with the pressure recorded and a stepper experiment of one robot, alone and jointly |
| `benchmarks/population.py` | populations of eight robots on one drawn rig: coverage of the population's median and spread, and of a held-out robot's predictive band |
| `benchmarks/discover_discrepancy.py` | discovery's answer on data with a discrepancy but no catalogue effect |
| `benchmarks/design.py` | the designed experiment: the criterion against random admissible inputs and the published pulse train, and replications on drawn rigs, predicted sd against realised; `design_discrimination`: `--discriminate A B --duration 3 --knot-spacing 0.1 --random 16 --replications 10` (discovery's verdicts under the discrimination design and the published pulse train, on data from each effect and on clean data); `design_discrimination_pair`: the same with `--candidates retraction_folding trapped_air --inputs design --random 16 --starts 1 --iterations 10` (discovery choosing between the two rivals, under the design); `design_discrimination_pair_held`: `--design-from` that file `--truths retraction_folding --hold-base` (the same design's data, discovery holding Y at the first experiment's estimate); `design_discrimination_pair_first`: `--design-from` that file `--truths retraction_folding none --with-first` (each seed's designed experiment read together with the first one made again on the same robot: `growjax.discover.discover_set` over the two, one Y); `design_discrimination_pair_first_air`: the same with `--truths trapped_air`; `design_discrimination_catalogue_first`: the same with every catalogue effect as a candidate (`--candidates` the eight), `--truths retraction_folding none --replications 2 --workers 2`; `design_lockhart`: `--growth-law lockhart --for Y phi_L n_L --random 64 --starts 2 --iterations 20` then `--design-from` it `--replications 20` (the design under Lockhart's law, its rate's and exponent's intervals against their prior box); `design_lockhart_20s`: the same law's design over 20 s by `growjax design --law lockhart --for Y phi_L n_L --duration 20`, then `--design-from` its `summary.json` `--duration 20 --replications 10 --inputs design --safety-draws 0`; `design_relinearised`: `--design-from design.json --relinearise` (the same replications, fitted with the rig relinearised); `design_landscape`: `--random 1000 --replications 0 --safety-draws 0` (the design against 1 000 random admissible inputs), then `--design-from` that file `--replications 20 --workers 2 --relinearise` (its replications and safety, the default fit); `design_landscape_tangents`: the same replications fitted with `--rig-tangents` (`growjax.calibration.fit.fit(rig_tangents=True)`); `design_stepper`: `--next-drive inverse --design-from` the `summary.json` of `growjax design src/growjax/data/datasets/synthetic_forward.csv --next-drive inverse --for Y` `--replications 20 --workers 2` (the stepper's designed schedule against the stepper driven by the recorded length); `design_stepper_discrepancy`: the same with `--discrepancy-in-data --safety-draws 0` (the replications' data also carry a fresh draw of the discrepancy the first fit found) |
| `benchmarks/track.py` | the length from the pump's own sensors (pressure and syringe) on reference-made records of 20 rigs drawn from the tolerance budget, 10 s of the published pulse, and three 60 s records with Y rising by 10 %: length RMSE and the 90 % band's coverage, the innovations' NIS, the rig's NEES, the filter's step against `simulate_from`, a smoothed record; extended against unscented Kalman |
| `benchmarks/track_libraries.py` | growjax's extended Kalman filter against dynamax's (and its iterated form) on the same model and record |
| `benchmarks/least_squares.py` | growjax's Levenberg–Marquardt engine against optimistix's solvers on the fit's and the control profile's problems; `least_squares_linearize`: `--cases fit_Y --solvers lm_linearize --out benchmarks/results/least_squares_linearize.json` (optimistix linearising the model itself) |
"""


def _ms(x) -> str:
    return f"{1e3 * float(x):.1f} ms"


def _s(x) -> str:
    return f"{float(x):.2f} s"


def rows_simulate(r: dict) -> list[tuple[str, str, str]]:
    sim, grad = r["simulation"], r["gradient"]
    out = [
        (
            "one 10 s simulation, fast configuration",
            _ms(sim["wall_s"]),
            f"compile {_s(sim['compile_s'])}, {sim['solver_steps']} steps",
        ),
        (
            "forward-mode gradient of the 10 s log-likelihood in (Y, ext, n)",
            _ms(grad["wall_s"]),
            f"compile {_s(grad['compile_s'])}",
        ),
    ]
    for run in r.get("other_runs", []):
        out.append((f"{run['drive']} drive, rtol {run['rtol']:g}", _ms(run["wall_s"]), f"{run['solver_steps']} steps"))
    return out


def rows_sweep(r: dict) -> list[tuple[str, str, str]]:
    s, b = r["sweep"], r["scipy_baseline"]
    n = s.get("n", "")
    out = [
        (
            f"{n}-set sweep, after compilation",
            _s(s["wall_s"]),
            f"compile {_s(s['compile_s'])}, {r.get('n_devices', 1)} devices",
        ),
        (f"SciPy BDF baseline for {n} sets (extrapolated)", _s(b["wall_s_for_n"]), ""),
        ("baseline ÷ sweep", f"{r['ratios']['baseline_over_sweep']:.0f}×", ""),
    ]
    if "cli_process" in r:
        out.append(("whole `growjax sweep` process", _s(r["cli_process"]["process_wall_s"]), "cold cache"))
    return out


def rows_agreement(r: dict) -> list[tuple[str, str, str]]:
    s = r["summary"]
    return [
        (
            "fast vs reference, length RMSE (worst case)",
            f"{s['rmse_mm_max']:.3f} mm",
            f"{s['n_compared']} of {s['n']} cases, target {s['targets']['rmse_mm']} mm",
        ),
        (
            "fast vs reference, largest length difference",
            f"{s['max_mm_max']:.3f} mm",
            f"target {s['targets']['max_mm']} mm",
        ),
        (
            "volume balance error, share of the delivered volume",
            f"{s['volume_defect_share_max']:.1e}",
            f"target {s['targets']['volume_defect_share']:g}",
        ),
    ]


def rows_generic(r: dict) -> list[tuple[str, str, str]]:
    scalars = {k: v for k, v in r.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    return [(k, f"{v:.4g}", "") for k, v in list(scalars.items())[:8]]


def rows_windows(r: dict) -> list[tuple[str, str, str]]:
    out = []
    for row in r["rows"].values():
        lo, hi = row["interval_90_Pa"]
        w = row["window_s"]
        out.append(
            (f"Y on {w[0]:g}–{w[1]:g} s, {row['likelihood']}", f"{row['Y_Pa']:.0f} Pa", f"90 % {lo:.0f}–{hi:.0f} Pa")
        )
    worst = {}
    for p in r["pairs"]:
        worst[p["likelihood"]] = max(worst.get(p["likelihood"], 0.0), p["z"])
    out += [
        (f"largest |ΔY| between disjoint windows, {k}", f"{v:.2f} combined se", "target ≤ 2") for k, v in worst.items()
    ]
    out.append(("0–10 s interval, share of the 5–15 kPa box", f"{r['interval_share_of_box']:.2f}", "target ≤ 0.33"))
    return out


def rows_coverage(r: dict) -> list[tuple[str, str, str]]:
    out = [
        (f"coverage of Y's 90 % interval, {g}", f"{s['coverage_90']:.2f}", f"{s['sets']} sets, target 0.80–0.97")
        for g, s in r["summary"].items()
    ]
    ratio = r["summary"].get("none", {}).get("width_ratio_vs_independent")
    if ratio:
        out.append(
            (
                "width against independent noise, white-noise data",
                f"{ratio['median']:.2f}",
                f"max {ratio['max']:.2f}, target ≤ 1.5",
            )
        )
    return out


def rows_predict(r: dict) -> list[tuple[str, str, str]]:
    return [
        (
            f"90 % band on the held-out window, {k}",
            f"{v['coverage_90_after_split']:.2f}",
            f"NUTS {v['wall_s']:.0f} s, R-hat {v['rhat_max']:.3f}, target 0.80–0.97",
        )
        for k, v in r.items()
        if isinstance(v, dict) and "coverage_90_after_split" in v
    ]


def rows_fit_speed(r: dict) -> list[tuple[str, str, str]]:
    out = [
        (
            f"fit, {k}: discrepancy ÷ independent noise",
            f"{v['ratio_warm']:.2f}",
            f"{v['discrepancy']['warm_s']:.2f} s against {v['independent']['warm_s']:.2f} s, target ≤ 1.5",
        )
        for k, v in r.items()
        if isinstance(v, dict) and "ratio_warm" in v
    ]
    out += [
        (
            f"fit, {k}: rig inferred ÷ rig fixed",
            f"{v['ratio_warm_inferred_over_fixed']:.2f}",
            f"{v['discrepancy']['warm_s']:.2f} s against {v['rig_fixed']['warm_s']:.2f} s",
        )
        for k, v in r.items()
        if isinstance(v, dict) and "ratio_warm_inferred_over_fixed" in v
    ]
    out += [
        (
            f"fit, {k}: the rig's tangents (default) ÷ its secants relinearised",
            f"{v['ratio_warm_over_secants']:.2f}",
            f"{v['discrepancy']['warm_s']:.2f} s against {v['secants']['warm_s']:.2f} s "
            f"({v['secants']['linearisations']} linearisations); first run {v['discrepancy']['first_s']:.1f} s "
            f"against {v['secants']['first_s']:.1f} s",
        )
        for k, v in r.items()
        if isinstance(v, dict) and "ratio_warm_over_secants" in v
    ]
    out += [
        (
            f"fit, {k}: the rig's tangents (default) ÷ its secants linearised once",
            f"{v['ratio_warm_over_once']:.2f}",
            f"{v['discrepancy']['warm_s']:.2f} s against {v['once']['warm_s']:.2f} s",
        )
        for k, v in r.items()
        if isinstance(v, dict) and "ratio_warm_over_once" in v
    ]
    return out


def rows_rig_agreement(r: dict) -> list[tuple[str, str, str]]:
    out = []
    for group, g in r["summary"].items():
        out.append(
            (
                f"{group}: coverage of Y's 90 %, fit with the rig inferred / fixed",
                f"{g['fit_inferred']['coverage_90']:.2f} / {g['fit_fixed']['coverage_90']:.2f}",
                f"{g['sets']} sets; median widths {g['fit_inferred']['median_width_Pa']:.0f} / "
                f"{g['fit_fixed']['median_width_Pa']:.0f} Pa; target 0.80–0.97",
            )
        )
        if "posterior" in g:
            ratio = g["width_ratio_fit_over_posterior"]
            out.append(
                (
                    f"{group}: width of the fit's interval ÷ the posterior's",
                    f"{ratio['median']:.2f}",
                    f"{ratio['min']:.2f}–{ratio['max']:.2f} over {g['posterior']['sets']} NUTS sets; target "
                    f"within 25 %",
                )
            )
            out.append(
                (
                    f"{group}: the posterior's replicated 90 % band",
                    f"{g['posterior']['band_coverage_90']:.3f}",
                    "share of the measured points inside it; target 0.85–0.95",
                )
            )
    return out


def rows_set_speed(r: dict) -> list[tuple[str, str, str]]:
    each = r.get("each_experiment_fit")
    return [
        *(
            [
                (
                    "joint fit of the set ÷ the mean of its experiments' single fits",
                    f"{r['ratio_set_over_mean_fit']:.1f}",
                    f"{r['set']['warm_s']:.1f} s against {each['mean_warm_s']:.1f} s warm (the eight alone: "
                    f"{min(each['warm_s']):.1f}–{max(each['warm_s']):.1f} s; fitting them one at a time takes "
                    f"{sum(each['warm_s']):.1f} s); target ≤ 3",
                )
            ]
            if each
            else []
        ),
        (
            "joint fit of the set ÷ its first experiment's fit",
            f"{r['ratio_set_over_one_fit']:.1f}",
            f"{r['set']['warm_s']:.1f} s against {r['one_experiment_fit']['warm_s']:.1f} s warm; "
            f"{100 * r['set_simulate_share']:.0f} % in the batched simulations" + ("" if each else "; target ≤ 3"),
        ),
        *(
            [
                (
                    "one evaluation of the model: the set batched ÷ one experiment",
                    f"{r['ratio_evaluation_set_over_one']:.1f}",
                    f"{r['evaluation']['set_s']:.3f} s against {r['evaluation']['one_s']:.3f} s; residuals and tangents in Y "
                    "and the rig's errors" + _devices(r),
                )
            ]
            if "evaluation" in r
            else []
        ),
    ]


def _devices(r: dict) -> str:
    """Where the set's runs were spread over several CPU devices: how many, and the same evaluation on one."""
    if r.get("devices", 1) < 2 or "set_one_device_s" not in r["evaluation"]:
        return ""
    return f"; spread over {r['devices']} CPU devices (on one device: {r['evaluation']['set_one_device_s']:.3f} s)"


def rows_population(r: dict) -> list[tuple[str, str, str]]:
    s = r["summary"]
    n = f"{s['populations']} populations of {s['robots']} robots"
    return [
        (
            "coverage of the population median's 90 % interval",
            f"{s['median_coverage_90']:.2f}",
            f"{n}; target 0.80–0.97",
        ),
        (
            "coverage of the population spread's 90 % interval",
            f"{s['spread_coverage_90']:.2f}",
            f"{n}; target 0.80–0.97",
        ),
        ("coverage of each robot's 90 % interval", f"{s['robot_coverage_90']:.2f}", n),
        (
            "a held-out robot's points inside its 90 % predictive band",
            f"{s['new_robot_band_coverage']:.3f}",
            "target 0.80–0.97",
        ),
        (
            "NUTS, 4 × (500 + 500), median",
            f"{s['median_nuts_s']:.2g} s",
            f"joint fit of the eight runs {s['median_fit_s']:.0f} s (median); target ≤ 15 min",
        ),
        *(
            [
                (
                    "NUTS divergences, most in one population",
                    f"{s['max_divergences']}",
                    f"of {_draws(r)} draws; populations with any: "
                    f"{sum(p['diagnostics']['divergences'] > 0 for p in r.get('populations', []))}",
                )
            ]
            if "max_divergences" in s
            else []
        ),
    ]


def _draws(r: dict) -> str:
    a = r.get("arguments", {})
    return f"{a.get('chains', 4) * a.get('samples', 500):,}".replace(",", " ")


def rows_sets(r: dict) -> list[tuple[str, str, str]]:
    s = r["summary"]
    return [
        (
            "joint Y: coverage of the 90 % interval",
            f"{s['joint']['coverage_90']:.2f}",
            f"{s['sets']} sets; median width {s['joint']['median_width_Pa']:.0f} Pa{_rms_z(s['joint'])}; "
            "target 0.80–0.97",
        ),
        (
            "joint Y narrower than the best single experiment's",
            f"{s['joint_narrower_than_best_single']:.2f}",
            "share of the sets; target ≥ 0.90",
        ),
        *_narrower_single(s),
        (
            "rig errors taken per experiment: coverage",
            f"{s['joint_independent_rig']['coverage_90']:.2f}",
            f"median width {s['joint_independent_rig']['median_width_Pa']:.0f} Pa{_rms_z(s['joint_independent_rig'])}",
        ),
        (
            "single experiments: coverage",
            f"{s['single']['coverage_90']:.2f}",
            f"median width {s['single']['median_width_Pa']:.0f} Pa{_rms_z(s['single'])}",
        ),
    ]


def _rms_z(group: dict) -> str:
    """ "; rms z …" where the results carry the rms of (estimate − truth) / sd."""
    return f"; rms (estimate − truth)/sd {group['rms_z']:.2f}" if "rms_z" in group else ""


def _narrower_single(s: dict) -> list[tuple[str, str, str]]:
    n = s.get("narrower_single")
    if not n or not n["sets"]:
        return []
    return [
        (
            "where a single experiment is narrower: it covers",
            f"{n['covered']} of {n['sets']}",
            f"median abs (estimate − truth)/sd of that single {n['median_abs_z']:.1f}",
        )
    ]


def rows_mixed_set(r: dict) -> list[tuple[str, str, str]]:
    truth = r["truth_Pa"]
    out = []
    for label, what in (
        ("forward", "forward drive, length and pressure, alone"),
        ("stepper", "stepper drive alone"),
        ("joint", "both jointly, one rig"),
    ):
        x = r[label]
        lo, hi = x["interval_90_Pa"]
        out.append(
            (
                f"Y, {what}",
                f"{x['estimate_Pa']:.0f} Pa [{lo:.0f}, {hi:.0f}]",
                f"truth {truth:.0f} Pa; {x['wall_s']:.0f} s, {x['programs']} compiled program(s)",
            )
        )
    (lf, hf), (ls, hs) = r["forward"]["interval_90_Pa"], r["stepper"]["interval_90_Pa"]
    overlap = max(lf, ls) <= min(hf, hs)
    out.append(("the two experiments' intervals overlap", "yes" if overlap else "no", "Y consistent across drives"))
    return out


def rows_discover_discrepancy(r: dict) -> list[tuple[str, str, str]]:
    return [
        (
            "answer `none`, no catalogue effect but a discrepancy",
            f"{r['none']} of {r['sets']}",
            f"{r['t_end_s']:g} s windows, target ≥ 19 of 20",
        )
    ]


def rows_discover(r: dict) -> list[tuple[str, str, str]]:
    hidden = [x for x in r["runs"] if x["effect"] is not None]
    clean = [x for x in r["runs"] if x["effect"] is None]
    factors = ", ".join(f"{f:g}×" for f in r.get("factors", []))
    out = [("rig's tolerances", r.get("rig", "default tolerance budget"), f"magnitude {factors} moderate")]
    for effect in r["named_share_per_effect"]:
        mine = [x for x in hidden if x["effect"] == effect]
        if not mine:
            continue
        confounded = sum(x["confounded"] for x in mine)
        out.append(
            (
                f"`{effect}` named",
                f"{sum(x['named'] for x in mine)} of {len(mine)}",
                f"{confounded} confounded" if confounded else "",
            )
        )
    if clean:
        out.append(
            (
                "false positives on clean data",
                f"{sum(x['found'] != 'none' for x in clean)} of {len(clean)}",
                "target ≤ 1 of 20",
            )
        )
    out.append(("a wrong effect claimed", f"{r['wrong_effect_share']:.2f}", "share of hidden-effect runs"))
    out.append(("median wall time of a run", _s(r["median_wall_s"]), ""))
    if r.get("wall_ratio_to_independent"):
        out.append(
            (
                "wall time against independent noise",
                f"{r['wall_ratio_to_independent']:.2f}",
                f"{len(r['baseline_runs'])} clean seeds, target ≤ 1.5",
            )
        )
    return out


def rows_control(r: dict) -> list[tuple[str, str, str]]:
    out = [
        (
            name,
            f"{1e3 * m['tracking_rmse_m']:.2f} mm",
            (f"peak {m['peak_pressure_Pa'] / 1e3:.0f} kPa, evaluated on the {r['evaluated_on']} configuration"),
        )
        for name, m in r["methods"].items()
    ]
    out.append(("MPC time per tick, median", f"{1e3 * r['mpc_step_s_median']:.1f} ms", ""))
    out.append(("profile optimisation", _s(r["profile_optimisation_s"]), ""))
    return out


def rows_least_squares(r: dict) -> list[tuple[str, str, str]]:
    out = []
    for label, problem in r["problems"].items():
        out.append(
            (
                f"**{label}**",
                "median warm",
                f"{problem['description']}; cost ½‖r‖² of the point reached; "
                "first calls in one process in this order (a later one may reuse traces of the model an "
                "earlier one made)",
            )
        )
        for name, s in problem["solvers"].items():
            steps = f"{s['steps']} steps" + (f" ({s['evaluations']} evaluations)" if name == "engine" else "")
            note = [
                f"first {_s(s['first_s'])}",
                steps,
                f"cost {s['cost']:.6g}",
                "converged" if s["converged"] else "not converged",
            ]
            if "warm_over_engine" in s:
                note.insert(0, f"{s['warm_over_engine']:.1f}× the engine")
                note.insert(4, f"{s['cost_over_engine']:+.1e} relative")
            if "distance_se" in s:
                note.append(f"{s['distance_se']:.2g} standard errors from the engine's point")
            if s["outside_box"]:
                note.append(f"{s['outside_box']} outside the box")
            elif s["on_bound"]:
                note.append(f"{s['on_bound']} on a bound")
            out.append((f"{label}, {name}", _s(s["warm_s"]), ", ".join(note)))
        out.append(
            (
                f"{label}, verdict",
                problem["verdict"],
                f"an optimistix solver would replace the engine converged, within {r['within_warm_ratio']:g}× its "
                f"warm time, at a cost at most {r['same_cost_relative']:g} relative above its, inside the box; "
                f"the solve carrying sensitivities moves the cost by {problem['cost_noise_relative']:.0e} relative",
            )
        )
    return out


def rows_sweep_resume(r: dict) -> list[tuple[str, str, str]]:
    full, cut, resumed = r["uninterrupted"], r["interrupted"], r["resumed"]
    same = r["identical"]
    return [
        (
            "resumed table identical to the uninterrupted one",
            "yes" if same["all"] else "no",
            f"sweep.csv {'identical' if same['sweep_csv'] else 'different'}, the store's arrays "
            f"{'identical' if all(same['store_arrays'].values()) else 'different'}, bit for bit",
        ),
        (
            "chunks done when the SIGINT stopped it",
            f"{cut['chunks_done']} of {r['chunks']}",
            f"{r['n']} sets in chunks of {r['chunk_size']}, {r['n_devices']} devices; exit status {cut['exit_status']}",
        ),
        (
            "uninterrupted `growjax sweep` process (T)",
            _s(full["process_wall_s"]),
            f"sweep loop {_s(full['sweep_wall_s'])}; compilation cache warm",
        ),
        (
            "`growjax sweep --resume` process (R)",
            _s(resumed["process_wall_s"]),
            f"sweep loop {_s(resumed['sweep_wall_s'])}",
        ),
        (
            "R ÷ (remaining share f × T)",
            f"{r['ratio_process']:.2f}",
            f"f = {r['remaining_share']:.2f}; sweep loops alone {r['ratio_sweep_loop']:.2f}; "
            f"target ≤ {r['target_ratio']:g}",
        ),
    ]


def rows_design(r: dict) -> list[tuple[str, str, str]]:
    land, rep = r["landscape"], r["replications"]
    baseline = next(label for label in rep if label not in ("design", "design_over_published_realised_sd"))
    out = [
        (
            "criterion, ln of the predicted variance of ln θ (lower is better): design / best random input / "
            f"{baseline}",
            f"{land['design_criterion']:.4f} / {land['random_best_criterion']:.4f} / {land['published_criterion']:.4f}",
            f"{land['random_admissible']} admissible of {land['random_drawn']} random inputs (their criterion's 10/50/90 % "
            f"quantiles {' / '.join(f'{v:.2f}' for v in land['random_quantiles'].values())}); design beats the best: "
            f"{'yes' if land['design_beats_best_random'] else 'no'}",
        )
    ]
    for label in ("design", baseline):
        for name, g in rep[label].items():
            if g["realised_sd_log"] is None:
                continue
            out.append(
                (
                    f"{label}: {name}, realised sd of ln θ̂ / predicted",
                    f"{100 * g['realised_sd_log']:.2f} % / {100 * g['predicted_sd_log_alone']:.2f} %",
                    f"{g['replications']} replications; ratio {g['realised_over_predicted']:.2f} (target 0.75–1.25); "
                    f"fits' mean reported sd {100 * g['mean_reported_sd_log']:.2f} %; "
                    f"coverage {g['coverage_90']:.2f} (target 0.80–0.97)"
                    + (f"; {g['far_off']} settled more than 5 reported sd off" if g.get("far_off") else ""),
                )
            )
    for name, ratio in rep["design_over_published_realised_sd"].items():
        if ratio is not None:
            out.append((f"{name}: design's realised sd / the {baseline}'s", f"{ratio:.2f}", "target ≤ 0.5"))
    safe = r.get("safety")
    for label in ("design", baseline) if safe else ():
        g = safe[label]
        out.append(
            (
                f"{label}: runs over the membrane limit / over the stroke (reference configuration)",
                f"{g['over_membrane_limit']} / {g['over_stroke']} of {safe['draws']}",
                f"fresh draws of the rig and θ; worst {g['peak_pressure_Pa'] / 1e3:.1f} kPa (limit "
                f"{safe['limits']['membrane_limit_Pa'] / 1e3:.1f}), {1e3 * g['peak_length_m']:.1f} mm (stroke "
                f"{1e3 * safe['stroke_m']:.0f}); over the {safe['limits']['pressure_ceiling_Pa'] / 1e3:.0f} kPa "
                f"ceiling: {g['over_pressure_ceiling']}; completed {g['runs_completed']}",
            )
        )
    return out


def rows_design_discrimination(r: dict) -> list[tuple[str, str, str]]:
    out = [
        (f"min T: {row['input']}", f"{min(row['T'].values()):.1f}", "threshold 6.24") for row in r["design"]["table"]
    ]
    for label, rates in r["named_rate"].items():
        for effect, rate in rates.items():
            n = sum(1 for x in r["replications"] if x["truth"] == effect)
            what = (
                "discovery names no effect on clean data"
                if effect == "none"
                else f"discovery names {effect} when it is hidden"
            )
            out.append((f"{label}: {what}", f"{rate:.2f}", f"{n} seeds (target ≥ 0.9)"))
    return out


def rows_design_lockhart(r: dict) -> list[tuple[str, str, str]]:
    """The design rows, and each growth-law parameter's 90 % interval over the replications as a share of its
    prior box (the sampling box the fit's undetermined parameters take)."""
    import growjax as gj
    from growjax.calibration import default_range

    out = rows_design(r)
    base = gj.reference(growth_law=r["arguments"].get("growth_law", "reference"))
    for label in ("design", "published pulse train"):
        fits = [
            row[label] for row in r.get("rows", []) if row.get(label, {}).get("status") in ("converged", "max_steps")
        ]
        for name in ("robot.lockhart_rate", "robot.lockhart_exponent"):
            if not fits or name not in fits[0]:
                continue
            lo, hi = default_range(base, name)
            shares = [
                np.log(f[name]["interval_90"][1] / f[name]["interval_90"][0]) / np.log(hi / lo)
                if f[name]["interval_90"]
                else np.inf
                for f in fits
            ]
            out.append(
                (
                    f"{label}: {name}, 90 % interval / its prior box (ln widths), median (worst)",
                    f"{np.median(shares):.2f} ({np.max(shares):.2f})",
                    f"{len(fits)} replications; box {lo:g}–{hi:g}; target ≤ 0.33; at most ⅓ in "
                    f"{sum(s <= 1 / 3 for s in shares)}",
                )
            )
    return out


def rows_track(r: dict) -> list[tuple[str, str, str]]:
    base = r["baseline"]["step_median_s"]
    out = [("`simulate_from` over one 10 ms interval (baseline)", _ms(base), "nominal rig, no filter")]
    for name, m in r["methods"].items():
        s = m["summary"]
        lo, hi = r["targets"]["coverage"]
        out += [
            (
                f"{name}: length RMSE, mean / worst",
                f"{1e3 * s['rmse_mean_m']:.3f} / {1e3 * s['rmse_worst_m']:.3f} mm",
                f"≤ 0.5 mm on {s['rmse_met']} of {s['records']} rigs (target: all)",
            ),
            (
                f"{name}: share of samples inside the 90 % band, mean (lowest rig)",
                f"{s['coverage_mean']:.2f} ({s['coverage_min']:.2f})",
                f"target {lo:g}–{hi:g}",
            ),
            (
                f"{name}: NIS per reading; NEES of the rig's 6 errors at 10 s",
                f"{s['nis_per_reading_mean']:.2f}; {s['nees_rig_mean']:.1f}",
                "honest: 1; 6",
            ),
            (
                f"{name}: step, median (90th percentile)",
                f"{_ms(s['step_median_s'])} ({_ms(s['step_p90_s'])})",
                f"{0.01 / s['step_median_s']:.0f}× real time; {s['step_median_s'] / base:.1f}× `simulate_from`; "
                "target ≤ 1 ms",
            ),
            (f"{name}: a 10 s record tracked and smoothed", _s(m["smooth_10s_s"]), "target ≤ 5 s"),
        ]
        d = m.get("drift_summary")
        if d:
            out.append(
                (
                    f"{name}, Y +10 % over 60 s: length RMSE; band; Y's band",
                    f"{1e3 * d['rmse_mean_m']:.3f} mm; {d['coverage_mean']:.2f}; {d['y_coverage_mean']:.2f}",
                    f"{d['records']} records; shares of samples inside the 90 % bands",
                )
            )
    out.append(
        ("load average during the run", f"{r['load_average'][0]:.1f}", "a shared machine: times are upper bounds")
    )
    return out


def rows_track_libraries(r: dict) -> list[tuple[str, str, str]]:
    return [
        (
            name,
            f"{1e3 * row['rmse_m']:.3f} mm, band {row['coverage_90']:.2f}",
            f"first call {_s(row['first_s'])}, record {_s(row['record_s'])}",
        )
        for name, row in r["rows"].items()
    ]


EXTRACTORS = {
    "design": rows_design,
    "design_stepper": rows_design,
    "design_stepper_discrepancy": rows_design,
    "design_relinearised": rows_design,
    "design_landscape": rows_design,
    "design_landscape_tangents": rows_design,
    "design_discrimination": rows_design_discrimination,
    "design_discrimination_pair": rows_design_discrimination,
    "design_discrimination_pair_held": rows_design_discrimination,
    "design_discrimination_pair_first": rows_design_discrimination,
    "design_discrimination_pair_first_air": rows_design_discrimination,
    "design_discrimination_catalogue_first": rows_design_discrimination,
    "design_lockhart": rows_design_lockhart,
    "design_lockhart_pressure": rows_design_lockhart,
    "design_lockhart_20s": rows_design_lockhart,
    "simulate": rows_simulate,
    "sweep": rows_sweep,
    "agreement": rows_agreement,
    "windows_public": rows_windows,
    "coverage_discrepancy": rows_coverage,
    "coverage_discrepancy_nominal": rows_coverage,
    "predict_public": rows_predict,
    "fit_speed": rows_fit_speed,
    "discover_discrepancy": rows_discover_discrepancy,
    "discover_discrepancy_3s": rows_discover_discrepancy,
    "coverage_discrepancy_rig": rows_coverage,
    "coverage_discrepancy_default_budget": rows_coverage,
    "coverage_discrepancy_default_budget_once": rows_coverage,
    "coverage_discrepancy_tangents": rows_coverage,
    "discover": rows_discover,
    "discover_rig_known": rows_discover,
    "discover_folding_twofold": rows_discover,
    "discover_folding_no_catheter_tolerance": rows_discover,
    "agreement_quick": rows_agreement,
    "control": rows_control,
    "least_squares": rows_least_squares,
    "least_squares_linearize": rows_least_squares,
    "rig_agreement": rows_rig_agreement,
    "set_speed": rows_set_speed,
    "population": rows_population,
    "sets": rows_sets,
    "sets_relinearised_singles": rows_sets,
    "sweep_resume": rows_sweep_resume,
    "mixed_set": rows_mixed_set,
    "track": rows_track,
    "track_libraries": rows_track_libraries,
}


def environment_line(r: dict, path: Path) -> str:
    env = r.get("environment")
    if not env:
        return "machine and versions not recorded (rerun the script)"
    return f"{env['machine']} ({env['device']}); Python {env['python']}, jax {env['jax']}, growjax {env['growjax']}"


def section(path: Path) -> str:
    """The page's section of one results file: heading, machine and versions, table."""
    try:
        r = json.loads(path.read_text())
        rows = EXTRACTORS.get(path.stem, rows_generic)(r)
    except (KeyError, TypeError, ValueError) as err:
        rows, r = [("could not be read", type(err).__name__, str(err)[:60])], {}
    data = f"; data: {Path(r['data']).name}" if r.get("data") else ""
    head = f"## {path.stem}\n\n{environment_line(r, path)}{data}\n\n| measurement | value | note |\n|---|---|---|\n"
    return head + "".join(f"| {a} | {b} | {c} |\n" for a, b, c in rows)


HEADING = re.compile(r"^## (\S+)[ \t]*$", re.MULTILINE)


def sections(page: str) -> dict[str, str]:
    """{name: text} of the results sections of a page :func:`render` wrote, each from its heading to the next."""
    marks = list(HEADING.finditer(page))
    ends = [m.start() for m in marks[1:]] + [len(page)]
    return {m.group(1): page[m.start() : end].rstrip("\n") + "\n" for m, end in zip(marks, ends)}


def table_rows(text: str) -> list[list[str]]:
    """The (measurement, value, note) rows of a section's table."""
    rows = []
    for line in text.splitlines():
        if line.startswith("| ") and line.endswith(" |") and not line.startswith("| measurement | value |"):
            rows.append([c.strip() for c in line[2:-2].split(" | ")])
    return rows


def render(results: Path, kept: dict | None = None) -> str:
    """The page from the results files in ``results``; ``kept`` {name: section text}: sections shown as they are
    where ``results`` has no file of that name."""
    files = {p.stem: p for p in sorted(results.glob("*.json"))} if results.is_dir() else {}
    kept = {k: v for k, v in (kept or {}).items() if k not in files}
    names = sorted(set(files) | set(kept))
    parts = [HEADER]
    if not names:
        parts.append("\nNo results yet: run a benchmark script, then `python benchmarks/report.py`.\n")
    for name in names:
        parts.append("\n" + (section(files[name]) if name in files else kept[name]))
    return "".join(parts)


def main(argv=None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", default=str(REPO / "benchmarks" / "results"))
    parser.add_argument("--out", default=str(REPO / "docs" / "benchmarks.md"))
    parser.add_argument(
        "--drop-missing",
        action="store_true",
        help="remove the page's sections whose results file is absent (default: keep them)",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    kept = {} if args.drop_missing or not out.exists() else sections(out.read_text())
    out.write_text(render(Path(args.results), kept))
    print("wrote", out)
    return out


if __name__ == "__main__":
    main()
