"""The rows of the Benchmarks page: one figure each, with its target and whether it was met; the speed topics'
rows from their results files."""

from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class Row:
    """One measured figure. ``met`` is None where the figure has no target; ``why`` says briefly why a target was
    missed; ``timed``: a wall time, so the machine's load bears on it."""

    measured: str
    value: str
    target: str = ""
    met: bool | None = None
    why: str = ""
    timed: bool = False


def info(measured: str, value: str) -> Row:
    """A figure shown for information, with no target."""
    return Row(measured, value)


def at_most(measured: str, x: float, limit: float, fmt, *, why: str = "above the target", timed=False) -> Row:
    return Row(measured, fmt(x), f"≤ {fmt(limit)}", bool(x <= limit), "" if x <= limit else why, timed)


def at_least(measured: str, x: float, limit: float, fmt, *, why: str = "below the target", timed=False) -> Row:
    return Row(measured, fmt(x), f"≥ {fmt(limit)}", bool(x >= limit), "" if x >= limit else why, timed)


def within(measured: str, x: float, lo: float, hi: float, fmt=None) -> Row:
    fmt = fmt or (lambda v: f"{v:.2f}")
    why = "below the band" if x < lo else "above the band" if x > hi else ""
    return Row(measured, fmt(x), f"{fmt(lo)}–{fmt(hi)}", bool(lo <= x <= hi), why)


def ms(x) -> str:
    return f"{1e3 * float(x):.1f} ms"


def s(x) -> str:
    return f"{float(x):.2f} s"


def times(x) -> str:
    return f"{float(x):.1f}×"


def ratio(x) -> str:
    return f"{float(x):.2f}"


# -- speed ---------------------------------------------------------------------------------------------------------


def simulate(r: dict) -> list[Row]:
    sim, grad, target = r["simulation"], r["gradient"], r.get("targets", {})
    rows = [
        at_most(
            "one 10 s simulation, fast configuration", sim["wall_s"], target.get("simulate_s", 0.02), ms, timed=True
        ),
        at_most(
            "forward-mode gradient of the 10 s log-likelihood in (Y, ext, n)",
            grad["wall_s"],
            target.get("gradient_s", 0.06),
            ms,
            timed=True,
        ),
        info("compile time of the simulation (cold, no cache)", s(sim["compile_s"])),
    ]
    for run in r.get("other_runs", []):
        drive = "stepper drive" if run["drive"] == "inverse" else f"{run['drive']} drive"
        rows.append(info(f"one 10 s simulation, {drive}, rtol {run['rtol']:g}", ms(run["wall_s"])))
    return rows


def sweep(r: dict) -> list[Row]:
    sw, base, ratios, n = r["sweep"], r["scipy_baseline"], r["ratios"], r["sweep"]["n"]
    rows = [
        at_most(f"{n}-set Latin-hypercube sweep, after compilation", sw["wall_s"], 1.0, s, timed=True),
        info(f"compile time of the {n}-set sweep", s(sw["compile_s"])),
        info(f"SciPy BDF for {n} sets, one core (from {base['sets_timed']} sets)", s(base["wall_s_for_n"])),
        at_least("SciPy ÷ the sweep after compilation", ratios["baseline_over_sweep"], 50, times, timed=True),
    ]
    cli = r.get("cli_process")
    if cli:
        rows.append(info(f"whole `growjax sweep` process, {cli['n']} sets, empty cache", s(cli["process_wall_s"])))
        rows.append(at_least("SciPy ÷ the whole process", ratios["baseline_over_cli_process"], 50, times, timed=True))
    worst = max((row["max_abs_length_difference_m"] for row in r.get("baseline_agreement", [])), default=None)
    if worst is not None:
        rows.append(
            at_most("SciPy against growjax, largest length difference", worst, 1e-4, lambda v: f"{1e3 * v:.2g} mm")
        )
    if n != 500:  # the targets are set for 500 sets
        rows = [replace(x, why=f"{x.why}; target set for 500 sets") if x.met is False else x for x in rows]
    return rows


def sweep_resume(r: dict) -> list[Row]:
    same = r["identical"]["all"]
    return [
        Row("resumed sweep's tables identical to the uninterrupted one's", "yes" if same else "no", "yes", same),
        at_most(
            "resumed process ÷ (share of chunks left × uninterrupted process)",
            r["ratio_process"],
            r.get("target_ratio", 1.2),
            ratio,
            timed=True,
        ),
    ]


def fit_speed(r: dict) -> list[Row]:
    rows = []
    for data, v in r.items():
        if not isinstance(v, dict) or "ratio_warm" not in v:
            continue
        rows += [
            info(f"fit of Y, {data} data, default likelihood", s(v["discrepancy"]["warm_s"])),
            at_most(
                f"that fit ÷ the independent-noise fit, {data} data",
                v["ratio_warm"],
                1.5,
                ratio,
                why=f"above the target: fitting the rig's errors beside Y (the default) takes "
                f"{ratio(v['ratio_warm_inferred_over_fixed'])} times as long as with the rig fixed",
                timed=True,
            ),
            info(f"that fit ÷ the rig-fixed fit, {data} data", ratio(v["ratio_warm_inferred_over_fixed"])),
        ]
    return rows


def set_speed(r: dict) -> list[Row]:
    evaluation = r.get("ratio_evaluation_set_over_one")
    why = "above the target"
    if evaluation is not None:
        why += f": one evaluation of the set's model (its runs over {r.get('devices', 1)} devices) costs "
        why += f"{ratio(evaluation)} times one experiment's"
    if r.get("each_experiment_fit"):
        ratio_of, label = r["ratio_set_over_mean_fit"], "that fit ÷ the mean single-experiment fit"
    else:
        ratio_of, label = r["ratio_set_over_one_fit"], "that fit ÷ its first experiment's fit"
    rows = [
        info("joint fit of a set of eight experiments", s(r["set"]["warm_s"])),
        at_most(label, ratio_of, 3, ratio, why=why, timed=True),
    ]
    if evaluation is not None:
        rows.append(info("one evaluation of the set's model ÷ one experiment's", ratio(evaluation)))
    return rows


def least_squares(r: dict) -> list[Row]:
    rows = []
    for label, problem in r["problems"].items():
        solvers = problem["solvers"]
        rows.append(info(f"Levenberg–Marquardt engine, {label}", s(solvers["engine"]["warm_s"])))
        others = {k: v for k, v in solvers.items() if k != "engine" and "warm_over_engine" in v}
        if others:
            best = min(others, key=lambda k: others[k]["warm_over_engine"])
            rows.append(
                info(
                    f"fastest optimistix solver ÷ the engine, {label} ({best})", times(others[best]["warm_over_engine"])
                )
            )
    return rows


def agreement(r: dict) -> list[Row]:
    sm, t = r["summary"], r["summary"]["targets"]
    mm = lambda v: f"{v:.3f} mm"  # noqa: E731
    return [
        at_most(
            f"fast against reference, worst length RMSE ({sm['n_compared']} cases)", sm["rmse_mm_max"], t["rmse_mm"], mm
        ),
        at_most("fast against reference, largest length difference", sm["max_mm_max"], t["max_mm"], mm),
        at_most(
            "volume balance error, share of the delivered volume",
            sm["volume_defect_share_max"],
            t["volume_defect_share"],
            lambda v: f"{v:.1e}",
        ),
    ]


def control(r: dict) -> list[Row]:
    rows = [
        info(
            f"tracking RMSE, {name} (on the {r['evaluated_on']} configuration)", f"{1e3 * m['tracking_rmse_m']:.2f} mm"
        )
        for name, m in r["methods"].items()
        if m.get("tracking_rmse_m") is not None
    ]
    if "mpc_step_s_median" in r:
        rows.append(info("MPC time per tick, median", ms(r["mpc_step_s_median"])))
    if "profile_optimisation_s" in r:
        rows.append(info("demand profile optimisation", s(r["profile_optimisation_s"])))
    return rows
