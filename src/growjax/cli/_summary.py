"""The command line's terminal summaries: a few lines per command, in mm and kPa."""

from __future__ import annotations

import json
from pathlib import Path


def _kpa(x) -> str:
    return "–" if x is None else f"{x / 1e3:.1f} kPa"


def _mm(x) -> str:
    return "–" if x is None else f"{1e3 * x:.2f} mm"


def _value(name: str, v: float) -> str:
    if name.endswith("yield_pressure") or name == "Y":
        return f"{v / 1e3:.3f} kPa"
    return f"{v:.4g}"


def _origin_lines(origin: dict) -> list[str]:
    lines = []
    if origin.get("recorded_beside_data"):
        shown = ", ".join(f"{k} = {_value(k, v)}" for k, v in origin["recorded_beside_data"].items())
        lines.append(f"  parameters recorded beside the data: {shown} (--param overrides)")
    if origin.get("fixed"):
        lines.append("  fixed by --param: " + ", ".join(f"{k} = {_value(k, v)}" for k, v in origin["fixed"].items()))
    return lines


def _simulate(s: dict, name: str) -> list[str]:
    lines = [
        f"simulate: {name}, {s['drive']} drive, {s['fidelity']} configuration, 0–{s['t_end_s']:g} s",
        *_origin_lines(s["parameters"]),
        (
            f"  status {s['status']}; final length {_mm(s['final_length_m'])}; peak pressure "
            f"{_kpa(s['peak_pressure_Pa'])} (membrane limit {_kpa(s['pressure_limit_Pa'])})"
        ),
    ]
    if "rmse_length_m" in s:
        lines.append(f"  length RMSE against the measured length: {_mm(s['rmse_length_m'])}")
    lines.append(
        f"  {s['solver_steps']} solver steps, {1e3 * s['wall_s']:.0f} ms after compiling "
        f"({s['first_call_s']:.1f} s first call)"
    )
    lines.append(f"  wrote {s['trajectory_csv']}, {s['figure']}")
    return lines


def _sweep(s: dict, name: str) -> list[str]:
    ranges = ", ".join(f"{r['name']} {r['low']:g}–{r['high']:g}" + (" (log)" if r["log"] else "") for r in s["ranges"])
    lines = [
        f"sweep: {name}, {s['n']} sets (seed {s['seed']}) over {ranges}",
        *_origin_lines(s["parameters"]),
        (
            f"  {s['n_failed']} failed; sweep {s['wall_s']:.2f} s after {s['compile_s']:.1f} s compiling, "
            f"{s['n_devices']} {s['device']} devices"
        ),
    ]
    if s.get("best"):
        best = ", ".join(f"{k} = {_value(k, v)}" for k, v in s["best"]["parameters"].items())
        lines.append(f"  best: {best}; length RMSE {_mm(s['best']['rmse_length_m'])}")
    for output, table in s.get("sobol", {}).get("indices", {}).items():
        if "S1" in table:
            shown = ", ".join(
                f"{n.split('.')[-1]} {a:.2f}/{b:.2f}" for n, a, b in zip(s["sobol"]["names"], table["S1"], table["ST"])
            )
            lines.append(f"  Sobol S1/ST of {output}: {shown}")
    lines.append(f"  wrote {s['table_csv']}, {s['figure']}")
    return lines


def _fit_set(s: dict) -> list[str]:
    runs = s["runs"]
    robots = len({r["robot"] for r in runs})
    rigs = len({r["rig"] for r in runs})
    lines = [
        f"fit: {len(runs)} experiments ({robots} robot{'s' * (robots > 1)}, {rigs} rig{'s' * (rigs > 1)}), "
        f"fitted jointly: {s['status']}"
    ]
    for p, v in s["parameters"].items():
        interval, name = v["interval_90"], p.split("@")[0]
        shown = (
            "undetermined" if interval is None else f"90 % {_value(name, interval[0])} – {_value(name, interval[1])}"
        )
        lines.append(f"  {p} = {_value(name, v['estimate'])} ({shown})")
        if v.get("budget_sd"):
            parts = sorted(v["budget_sd"].items(), key=lambda kv: -kv[1])[:5]
            lines.append("    sd from " + ", ".join(f"{k} {_value(p.split('@')[0], x)}" for k, x in parts if x > 0))
    if s.get("rig") == "inferred":
        for key, offsets in s.get("rig_offset", {}).items():
            shown = ", ".join(f"{k.split('.')[-1]} {100 * v:+.1f} %" for k, v in offsets.items())
            lines.append(f"  rig {key} inferred (its tolerances as priors): {shown}")
        if not s.get("rig_settled", True):
            lines.append(
                f"  note: the rig had not settled after {s['linearisations']} linearisations (its errors "
                f"still moved by {s['rig_last_move']:.2f} of a tolerance): Y trades with the rig along a "
                "direction these data hardly fix, and the interval is taken where the fit stopped"
            )
    elif s.get("rig") == "fixed":
        lines.append("  rig fixed at its nominal values, its tolerances propagated (--rig fixed)")
    for r in runs:
        lines.append(
            f"  {r['name']}: robot {r['robot']}, rig {r['rig']}, length RMSE {_mm(r['rmse_length_m'])}, "
            f"{r['samples_used']} samples scored"
        )
    lines.append(f"  {s['wall_s']:.1f} s ({s['simulate_s']:.1f} s in the batched simulations)")
    lines.append(f"  wrote {s['figure']}")
    return lines


def _fit(s: dict, name: str) -> list[str]:
    if "runs" in s:
        return _fit_set(s)
    lines = [
        f"fit: {name}, {s['drive']} drive, {s.get('t_start_s', 0.0):g}–{s['t_end_s']:g} s scored: {s['status']}",
        *_origin_lines(s["fixed_parameters"]),
    ]
    for p, v in s["parameters"].items():
        interval = v["interval_90"]
        shown = "undetermined" if interval is None else f"90 % {_value(p, interval[0])} – {_value(p, interval[1])}"
        lines.append(f"  {p} = {_value(p, v['estimate'])} ({shown})")
        if v.get("budget_sd"):
            parts = sorted(v["budget_sd"].items(), key=lambda kv: -kv[1])
            lines.append("    sd from " + ", ".join(f"{k} {_value(p, x)}" for k, x in parts if x > 0))
    d = s.get("discrepancy") or {}
    if d.get("kind") == "matern32":
        lines.append(
            f"  discrepancy {_mm(d['amplitude_m'])} over {d['time_scale_s']:.2g} s, noise "
            f"{_mm(d['noise_m'])} correlated over {1e3 * d.get('noise_time_s', 0.0):.2g} ms; "
            f"{s['samples_used']} samples scored"
        )
    elif d:
        lines.append(f"  independent noise {_mm(d['noise_m'])}")
    if s.get("rig") == "inferred" and s.get("rig_offset"):
        shown = ", ".join(f"{k} {100 * v:+.1f} %" for k, v in s["rig_offset"].items())
        lines.append(f"  rig inferred from the data (its tolerances as priors): {shown}")
    elif s.get("rig") == "fixed":
        lines.append("  rig fixed at its nominal values, its tolerances propagated (--rig fixed)")
    lines.append(f"  length RMSE {_mm(s['rmse_length_m'])}; {s['wall_s']:.1f} s")
    lines.append(f"  wrote {s['figure']}")
    return lines


def _posterior(s: dict, name: str) -> list[str]:
    if s.get("hierarchical"):
        return _population(s, name)
    lines = [
        (f"posterior: {name}, {s['growth_law']} growth law, {s['chains']} chains × ({s['warmup']} + {s['samples']})"),
        *_origin_lines(s["fixed_parameters"]),
    ]
    for p, v in s["parameters"].items():
        lo, hi = v["interval_90"]
        if p in ("sigma", "delta_amplitude"):
            label = "σ" if p == "sigma" else "discrepancy amplitude"
            lines.append(f"  {label} = {_mm(v['mean'])} (90 % {_mm(lo)} – {_mm(hi)})")
        elif p == "delta_time_scale":
            lines.append(f"  discrepancy time scale = {v['mean']:.2g} s (90 % {lo:.2g} – {hi:.2g} s)")
        elif p == "noise_time":
            lines.append(
                f"  noise correlation time = {1e3 * v['mean']:.2g} ms (90 % {1e3 * lo:.2g} – {1e3 * hi:.2g} ms)"
            )
        else:
            lines.append(f"  {p} = {_value(p, v['mean'])} (90 % {_value(p, lo)} – {_value(p, hi)})")
    lines.append(
        f"  R-hat max {s['rhat_max']:.3f}, bulk ESS min {s['ess_bulk_min']:.0f}, divergences "
        f"{s['divergences']}, measured points in the 90 % band {s['coverage_90']:.2f}; {s['wall_s']:.0f} s"
    )
    lines.append(f"  wrote {s['inference_data']}")
    return lines


def _population(s: dict, name: str) -> list[str]:
    p = s["parameter"]
    med, sd = s["population_median"], s["population_sd_log"]
    fit = s["joint_fit"]
    lines = [
        f"posterior: {name}, population of {len(s['robots'])} robots' {p}, {s['chains']} chains × "
        f"({s['warmup']} + {s['samples']}); the data through the joint fit ({fit['status']}, rig {fit['rig']})",
        f"  population median = {_value(p, med['median'])} (90 % {_value(p, med['interval_90'][0])} – "
        f"{_value(p, med['interval_90'][1])}); spread (sd of ln) = {sd['median']:.3f} "
        f"(90 % {sd['interval_90'][0]:.3f} – {sd['interval_90'][1]:.3f})",
    ]
    for robot, v in s["robot_posterior"].items():
        lines.append(
            f"  {robot}: {_value(p, v['median'])} (90 % {_value(p, v['lower_90'])} – {_value(p, v['upper_90'])})"
        )
    new = s["new_robot"]
    lo, hi = new["band_90_final_length_m"]
    lines.append(
        f"  a new robot under {new['input']}: final length {_mm(new['median_final_length_m'])} "
        f"(90 % {_mm(lo)} – {_mm(hi)}); median band width {_mm(new['median_band_width_m'])}"
    )
    d = s["diagnostics"]
    lines.append(
        f"  R-hat of mu {d['mu']['r_hat'] or float('nan'):.3f}, of s {d['s']['r_hat'] or float('nan'):.3f}; "
        f"ESS min {min(d[k]['ess'] for k in ('mu', 's', 'ln_theta')):.0f}; divergences {d['divergences']}; "
        f"{s['wall_s']:.0f} s"
    )
    lines.append(f"  wrote {s['posterior_file']}, {s['figure']}")
    return lines


def _discover(s: dict, name: str) -> list[str]:
    return [
        f"discover: {name}",
        *_origin_lines(s["fixed_parameters"]),
        *("  " + line for line in s["text"].splitlines()),
        *([f"  wrote {s['figure']}"] if "figure" in s else []),
    ]


def _control(s: dict, name: str) -> list[str]:
    lines = [
        (f"control: {name}, {s['drive']} drive, {s['method']}, evaluated on the {s['evaluated_on']} configuration"),
        *_origin_lines(s["fixed_parameters"]),
        (
            f"  tracking RMSE {_mm(s.get('tracking_rmse_m'))}; peak pressure {_kpa(s.get('peak_pressure_Pa'))} "
            f"(limit {_kpa(s.get('pressure_limit_Pa'))}, demand ceiling {_kpa(s.get('max_demand_Pa'))})"
        ),
    ]
    if s.get("gains"):
        lines.append(
            "  gains: "
            + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in s["gains"].items())
        )
    if s.get("figure"):
        lines.append(f"  wrote {s['figure']}")
    return lines


def _discrimination_rows(s: dict) -> list[str]:
    d = s["discrimination"]
    a, b = d["effects"]
    keys = (f"{a} real, {b} fitted", f"{b} real, {a} fitted")
    lines = [
        "  T: the expected 2ΔlogL by which the data reject the wrong effect (linearised; sizes "
        + ", ".join(f"{p} = {v:g}" for p, v in zip(d["parameters"], d["sizes"]))
        + f"); separates where min T > {d['threshold']:.2f}, the discovery's threshold",
        f"  {'input':24s} {'T (' + a + ' real)':>30s} {'T (' + b + ' real)':>30s} {'min T':>9s}  expected to separate",
    ]
    for row in s["table"]:
        lines.append(
            f"  {row['input']:24s} {row['T'][keys[0]]:30.2f} {row['T'][keys[1]]:30.2f} {row['T_min']:9.2f}  "
            f"{'yes' if row['expected_to_separate'] else 'no'}"
        )
    return lines


def _design(s: dict, name: str) -> list[str]:
    names = s["parameters"]
    if s.get("discrimination"):
        a, b = s["discrimination"]["effects"]
        lines = [
            f"design: {name}, to tell {a} from {b}, {s['duration_s']:g} s, demand in 0–{_kpa(s['p_max_Pa'])} on "
            f"knots every {s['knot_spacing_s']:g} s",
            *_origin_lines(s["fixed_parameters"]),
            *_discrimination_rows(s),
        ]
        return lines + _design_tail(s)
    if s.get("drive") == "inverse":
        space = (
            f"the stepper's schedule, up to one step of {_mm(s['metres_per_step'])} of length every "
            f"{1 / s['controller_rate_Hz']:.3g} s"
        )
    else:
        space = f"demand in 0–{_kpa(s['p_max_Pa'])} on knots every {s['knot_spacing_s']:g} s"
    lines = [
        f"design: {name}, {s['criterion']}-optimal for {', '.join(names)}, {s['duration_s']:g} s, {space}",
        *_origin_lines(s["fixed_parameters"]),
    ]
    head = f"  {'input':26s} {'sensors':16s}" + "".join(f" {n.split('.')[-1][:14]:>14s} sd  90 % width" for n in names)
    lines += [head + "   alone sd"]
    for row in s["table"]:
        cells = ""
        for n in names:
            p = row["parameters"][n]
            cells += f" {100 * p['sd_log']:16.2f} %  {_value(n, p['width_90']):>10s}"
        alone = ", ".join(f"{100 * row['parameters'][n]['sd_log_alone']:.2f} %" for n in names)
        lines.append(f"  {row['input']:26s} {'+'.join(row['sensors']):16s}{cells}   {alone}")
    return lines + _design_tail(s)


def _design_tail(s: dict) -> list[str]:
    lines = []
    check = s["checks"]["design"]
    lim = s["limits"]
    lines.append(
        f"  design over the draws: peak pressure {_kpa(check['peak_pressure_Pa'])} (ceiling "
        f"{_kpa(lim['pressure_ceiling_Pa'])}), peak length {_mm(check['peak_length_m'])} (ceiling "
        f"{_mm(lim['length_ceiling_m'])}): {'admissible' if check['admissible'] else 'NOT admissible'}"
    )
    r = s["random"]
    undefined = r.get("criterion_undefined", 0)
    lines.append(
        f"  {r['admissible']} random admissible inputs (of {r['drawn']} drawn"
        + (f"; {undefined} with no criterion: the model failed or they inform nothing" if undefined else "")
        + f"); {s['wall_s']['total_s']:.0f} s"
    )
    lines.append(f"  wrote {s['design_csv']}, {s['figure']}, {s['summary_json']}")
    return lines


def _params(s: dict, name: str) -> list[str]:
    lines = [f"{'name':34s} {'symbol':7s} {'value':>12s} {'unit':16s} {'physical range':24s} description"]
    for r in s["parameters"]:
        rng = "" if r["range"] is None else f"{r['range'][0]:g} – {r['range'][1]:g}"
        lines.append(
            f"{r['name']:34s} {r['symbol']:7s} {r['value']:12.5g} {r['unit']:16s} {rng:24s} {r['description'][:70]}"
        )
    return lines


def _effects(s: dict, name: str) -> list[str]:
    lines = []
    for r in s["effects"]:
        lines.append(f"{r['name']}: {r['description']}")
        lines.append(f"    parameter {r['parameter']} in [{r['range'][0]:g}, {r['range'][1]:g}] {r['unit']}")
        lines.append(f"    separated by: {r['separated_by']}")
    return lines


SUMMARIES = {
    "simulate": _simulate,
    "sweep": _sweep,
    "fit": _fit,
    "posterior": _posterior,
    "discover": _discover,
    "control": _control,
    "params": _params,
    "effects": _effects,
    "design": _design,
    "track": lambda s, name: _track_lines(s),
}  # command → its lines (summary, data name)


def _track_lines(s: dict) -> list[str]:
    from growjax.cli import track as track_command

    return track_command.summary_lines(s)


def summary_lines(s: dict) -> list[str]:
    """A few lines for the terminal, in mm and kPa."""
    command_lines = SUMMARIES.get(s.get("command"))
    if command_lines is None:
        return [json.dumps(s, default=str)]
    data = s.get("data")
    name = ", ".join(Path(d).name for d in data) if isinstance(data, list) else Path(data).name if data else ""
    return command_lines(s, name)
