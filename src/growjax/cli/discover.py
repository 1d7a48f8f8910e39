"""``growjax discover [DATA ...]``: which catalogue effect (`growjax effects`) the data need beyond the model, and
how sure; over several experiments (or a TOML manifest) by the set's joint fits. Writes discover.png."""

from __future__ import annotations

import time
from pathlib import Path

from growjax.cli import loader, options
from growjax.cli._summary import data_name, origin_lines
from growjax.cli.command import Process, note, out_dir
from growjax.cli.options import count, effect_name, listed, option

NAME = "discover"
HELP = "which catalogue effect the data need beyond the model (`growjax effects`)"
PROCESS = Process(cpu_devices=True)  # a set's runs spread over the cores
OPTIONS = (
    listed(
        "--candidates",
        item=effect_name,
        metavar="EFFECT[,...]",
        default=None,
        help="catalogue effects to test (default: every effect of `growjax effects`)",
    ),
    option(
        "--workers",
        type=count(),
        default=None,
        metavar="N",
        rare=True,
        help="fits run at a time (default: one per CPU core)",
    ),
)


def add_arguments(parser) -> None:
    """The shared options (several DATA), the candidates and workers, ``--quiet``, the likelihood's."""
    options.shared(parser, NAME, many=True)
    options.add(parser, OPTIONS)
    options.quiet(parser)
    options.likelihood(parser, NAME, rig=("inferred",), rig_errors=("shared",))


def run(args) -> dict:
    """Test each candidate effect on one experiment, or on a set; the summary."""
    paths = list(args.data or [])
    if len(paths) > 1 and any(Path(p).suffix.lower() == ".toml" for p in paths):
        raise ValueError("a manifest (.toml) describes the whole set: give it alone")
    data = loader.load(args)
    if not data.single:
        return _run_set(args, data)
    from growjax import discover as gd
    from growjax.plotting import discovery_figure

    exp, base = data.experiment, data.base()
    if "robot_length_m" not in exp:
        raise ValueError(f"{data.path} has no robot_length_m column to explain")
    config = options.make_config(args, args.drive, adjoint="forward")
    res = _discover(args, exp, base, config)
    figure = discovery_figure(res, out_dir(args) / "discover.png", title=f"{data.path.name}: {res.effect}")
    return {
        "command": NAME,
        "data": str(data.path),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fixed_parameters": data.origin,
        **res.report(),
        "figure": str(figure),
        "text": gd.summary_text(res),
    }


def _run_set(args, data) -> dict:
    """``growjax discover A.csv B.csv …`` or ``growjax discover SET.toml``: each effect tested by the set's joint
    fits, its parameter one value per robot."""
    from growjax import discover as gd

    config = options.make_config(args, args.drive, adjoint="forward")
    exps = data.experiments
    started = note(
        args,
        f"discover: {len(args.candidates or gd.fx.CATALOGUE)} candidates over "
        f"{len(exps)} experiments, one joint fit each",
    )
    res = _discover_set(args, exps, config)
    note(args, f"discover: done in {time.perf_counter() - started:.1f} s")
    return {
        "command": NAME,
        "data": list(data.sources),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fixed_parameters": data.origin,
        "experiments": [{"name": r.name, "robot": r.robot, "rig": r.rig, "window": r.window} for r in exps],
        **res.report(),
        "text": gd.set_summary_text(res),
    }


# -- the workflow's calls ---------------------------------------------------------------------------------------


def _discover(args, exp, base, config):
    """The discovery on one experiment's scored samples (`growjax.discover.discover` of its set of one)."""
    from growjax import discover as gd
    from growjax.data.sets import ExperimentSet

    one = ExperimentSet.single(
        exp,
        drive=args.drive,
        window=options.scored_window(args, config),
        sensors=("length",),
        defaults=base,
    )
    return gd.discover(
        one,
        config=config,
        candidates=args.candidates or None,
        progress=not args.quiet,
        workers=args.workers,
        likelihood=options.likelihood_of(args),
    )


def _discover_set(args, exps, config):
    """The discovery on a set, by its joint fits (`growjax.discover.discover`)."""
    from growjax import discover as gd

    return gd.discover(
        exps,
        config=config,
        candidates=args.candidates or None,
        seed=args.seed,
        likelihood=options.likelihood_of(args),
    )


def summary_lines(s: dict) -> list[str]:
    """The discovery's verdict, as its text says it, and the figure."""
    return [
        f"discover: {data_name(s)}",
        *origin_lines(s["fixed_parameters"]),
        *("  " + line for line in s["text"].splitlines()),
        *([f"  wrote {s['figure']}"] if "figure" in s else []),
    ]


__all__ = ["HELP", "NAME", "OPTIONS", "PROCESS", "add_arguments", "run", "summary_lines"]
