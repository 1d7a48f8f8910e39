"""``growjax fit [DATA ...]``: the least-squares fit of the free parameters to the measured length (and pressure),
their 90 % intervals; several experiments, or a TOML manifest, fitted jointly. Writes fit.png."""

from __future__ import annotations

import argparse
import time

from growjax.cli import loader, options
from growjax.cli._summary import data_name, mm, origin_lines, value
from growjax.cli.command import Process, RunFailed, note, out_dir
from growjax.cli.options import count, option

NAME = "fit"
HELP = "least-squares fit to the measured length (and pressure)"
PROCESS = Process(quick_compile=True, cpu_devices=True)  # a set's runs spread over the cores
OPTIONS = (
    option(
        "--free",
        action="append",
        default=[],
        metavar="NAME[@SCOPE]",
        help="parameter to fit (repeat; none: Y). With several experiments, @robot, @rig or "
        "@experiment fits one per robot, rig or experiment, none one for all (none given: Y@robot)",
    ),
    option("--starts", type=count(), default=3, help="starts, from the best sets of a Latin hypercube"),
)
RIG_OPTIONS = (
    option(
        "--rig",
        choices=["inferred", "fixed"],
        default="inferred",
        help="inferred: the toleranced rig parameters fitted beside the free ones, their tolerances "
        "as priors (the posterior's treatment); fixed: held nominal, each tolerance propagated "
        "as if the data said nothing of the rig (conservative)",
    ),
    option(
        "--rig-errors",
        choices=["shared", "experiment"],
        default="shared",
        help="with several experiments: one set of rig errors per rig, shared by its experiments, or "
        "one per experiment (treats them as independent: over-confident on one rig)",
    ),
    option(
        "--rig-tangents",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the rig inferred: the rig's errors are parameters of the model, their sensitivities its "
        "exact tangents, fitted with their priors before the discrepancy (default; reaches a rig "
        "far off nominal); --no-rig-tangents: the rig's secants from nominal, taken apart",
    ),
    option(
        "--relinearise",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="with --no-rig-tangents: take the secants again where the data put the rig, until it "
        "settles (default); --no-relinearise: once, at nominal (faster; over-confident where the "
        "rig is off by a tolerance or more)",
    ),
)


def add_arguments(parser) -> None:
    """The shared options (several DATA), the fit's, ``--quiet``, the likelihood's, the rig's."""
    options.shared(parser, NAME, many=True)
    options.add(parser, OPTIONS)
    options.quiet(parser)
    options.likelihood(parser)
    options.add(parser, RIG_OPTIONS)


def run(args) -> dict:
    """Fit one experiment, or a set jointly; the summary, RunFailed where the fit did not converge."""
    import growjax as gj
    from growjax.data import sets as xs
    from growjax.plotting import trajectory_figure

    data = loader.load(args)
    if not data.single:
        return _run_set(args, data)
    exp, base = data.experiment, data.base()
    if "robot_length_m" not in exp:
        raise ValueError(f"{data.path} has no robot_length_m column to fit")
    config = options.make_config(args, args.drive, adjoint="forward")
    exps = xs.ExperimentSet.single(
        exp,
        name=data.path.stem or "experiment",
        drive=args.drive,
        defaults=base,
        window=options.scored_window(args, config),
    )
    started = note(args, f"fit: {', '.join(args.free or ['Y'])} from {args.starts} starts")
    result = _fit(args, exps, args.free or ["Y"], config)
    note(args, f"fit: done in {time.perf_counter() - started:.1f} s")
    out = out_dir(args)
    run = exps.runs[0]
    fitted = result.parameters(run)
    traj = gj.simulate(fitted, run.model_inputs(fitted, config.t0, config.t1), config)
    fig = trajectory_figure(
        traj,
        out / "fit.png",
        measured=(exp.time, exp["robot_length_m"]),
        title=f"fit of {', '.join(result.labels)}: RMSE {1e3 * result.rmse_length_m:.2f} mm",
    )
    summary = {
        "command": NAME,
        "data": str(data.path),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "t_start_s": options.scored_window(args, config)[0],
        "fidelity": config.fidelity,
        "fixed_parameters": data.origin,
        **result.summary(),
        "figure": str(fig),
    }
    if result.status != "converged":
        raise RunFailed(
            f"the fit did not converge ({result.status}); try more --starts or fewer free parameters", summary
        )
    return summary


def _run_set(args, data) -> dict:
    """``growjax fit A.csv B.csv …`` or ``growjax fit SET.toml``: the experiments fitted jointly."""
    from growjax.data import sets as xs
    from growjax.plotting import set_figure

    config = options.make_config(args, args.drive, adjoint="forward")
    exps = data.experiments
    free = args.free or ["Y@robot"]
    scopes = [xs.Scope.parse(f, exps.runs[0].base()) for f in free]  # a bad scope is refused before any work
    started = note(args, f"fit: {', '.join(free)} over {len(exps)} experiments from {args.starts} starts")
    result = _fit(args, exps, scopes, config, scout=16)
    note(args, f"fit: done in {time.perf_counter() - started:.1f} s")
    fig = set_figure(_set_traces(args, exps, result, config), out_dir(args) / "fit.png")
    summary = {
        "command": NAME,
        "data": list(data.sources),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fidelity": config.fidelity,
        "free": list(free),
        "fixed_parameters": data.origin,
        "experiments": [
            {
                "name": r.name,
                "robot": r.robot,
                "rig": r.rig,
                "drive": r.drive,
                "window": r.window,
                "sensors": list(r.sensors),
            }
            for r in exps
        ],
        **result.summary(),
        "figure": str(fig),
    }
    if result.status != "converged":
        raise RunFailed(f"the joint fit did not converge ({result.status})", summary)
    return summary


def _set_traces(args, exps, result, config) -> list:
    """(name, trajectory at the fitted values, (times, measured length)) of each run of the set."""
    import growjax as gj

    traces = []
    for run in exps:
        base = result.parameters(run)
        cfg = config.replace(drive=run.drive)
        traj = gj.simulate(base, run.model_inputs(base, cfg.t0, cfg.t1), cfg)
        traces.append((run.name, traj, (run.times, run.length)))
    return traces


# -- the workflow's call ----------------------------------------------------------------------------------------


def _fit(args, exps, free, config, scout: int = 64):
    """The fit of the set (`growjax.calibration.fit`) under the flags' likelihood."""
    from growjax import calibration

    return calibration.fit(
        exps,
        free,
        likelihood=options.likelihood_of(args),
        config=config,
        starts=args.starts,
        scout=scout,
        seed=args.seed,
        relinearise=args.relinearise,
        rig_tangents=args.rig_tangents,
    )


# -- the summary for people -------------------------------------------------------------------------------------


def summary_lines(s: dict) -> list[str]:
    """The estimates with their intervals and sd budgets, the residual model, the rig, the RMSE and the figure."""
    if "experiments" in s:
        return _set_lines(s)
    lines = [
        f"fit: {data_name(s)}, {s['drive']} drive, {s.get('t_start_s', 0.0):g}–{s['t_end_s']:g} s scored: "
        f"{s['status']}",
        *origin_lines(s["fixed_parameters"]),
    ]
    for p, v in s["parameters"].items():
        interval = v["interval_90"]
        shown = "undetermined" if interval is None else f"90 % {value(p, interval[0])} – {value(p, interval[1])}"
        lines.append(f"  {p} = {value(p, v['estimate'])} ({shown})")
        if v.get("budget_sd"):
            parts = sorted(v["budget_sd"].items(), key=lambda kv: -kv[1])
            lines.append("    sd from " + ", ".join(f"{k} {value(p, x)}" for k, x in parts if x > 0))
    d = s.get("discrepancy") or {}
    if d.get("kind") == "matern32":
        lines.append(
            f"  discrepancy {mm(d['amplitude_m'])} over {d['time_scale_s']:.2g} s, noise "
            f"{mm(d['noise_m'])} correlated over {1e3 * d.get('noise_time_s', 0.0):.2g} ms; "
            f"{s['samples_used']} samples scored"
        )
    elif d:
        lines.append(f"  independent noise {mm(d['noise_m'])}")
    if s.get("rig") == "inferred" and s.get("rig_offset"):
        offsets = next(iter(s["rig_offset"].values()))  # the one run's rig
        shown = ", ".join(f"{k} {100 * v:+.1f} %" for k, v in offsets.items())
        lines.append(f"  rig inferred from the data (its tolerances as priors): {shown}")
    elif s.get("rig") == "fixed":
        lines.append("  rig fixed at its nominal values, its tolerances propagated (--rig fixed)")
    lines.append(f"  length RMSE {mm(s['rmse_length_m'])}; {s['wall_s']:.1f} s")
    lines.append(f"  wrote {s['figure']}")
    return lines


def _set_lines(s: dict) -> list[str]:
    runs = s["runs"]
    robots = len({r["robot"] for r in runs})
    rigs = len({r["rig"] for r in runs})
    lines = [
        f"fit: {len(runs)} experiments ({robots} robot{'s' * (robots > 1)}, {rigs} rig{'s' * (rigs > 1)}), "
        f"fitted jointly: {s['status']}"
    ]
    for p, v in s["parameters"].items():
        interval, name = v["interval_90"], p.split("@")[0]
        shown = "undetermined" if interval is None else f"90 % {value(name, interval[0])} – {value(name, interval[1])}"
        lines.append(f"  {p} = {value(name, v['estimate'])} ({shown})")
        if v.get("budget_sd"):
            parts = sorted(v["budget_sd"].items(), key=lambda kv: -kv[1])[:5]
            lines.append("    sd from " + ", ".join(f"{k} {value(p.split('@')[0], x)}" for k, x in parts if x > 0))
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
            f"  {r['name']}: robot {r['robot']}, rig {r['rig']}, length RMSE {mm(r['rmse_length_m'])}, "
            f"{r['samples_used']} samples scored"
        )
    lines.append(f"  {s['wall_s']:.1f} s ({s['simulate_s']:.1f} s in the batched simulations)")
    lines.append(f"  wrote {s['figure']}")
    return lines


__all__ = ["HELP", "NAME", "OPTIONS", "PROCESS", "RIG_OPTIONS", "add_arguments", "run", "summary_lines"]
