"""``growjax control [DATA]``: a length controller designed on the fast model to track DATA's length (an open-loop
profile or step schedule, tuned feedback, or MPC), evaluated on ``--evaluate-on``; writes control.png."""

from __future__ import annotations

import math
import time
from pathlib import Path

from growjax.cli import loader, options
from growjax.cli._summary import data_name, kpa, mm, origin_lines
from growjax.cli.command import Process, RunFailed, note, out_dir
from growjax.cli.options import count, option

NAME = "control"
HELP = "length control design: open-loop profile, feedback, MPC"
PROCESS = Process()
OPTIONS = (
    option(
        "--method",
        choices=["open-loop", "feedback", "mpc"],
        default="feedback",
        help="open-loop demand profile (or step schedule), tuned feedback, or MPC (forward drive)",
    ),
    option(
        "--evaluate-on",
        choices=options.FIDELITIES,
        default="reference",
        help="the configuration the design is evaluated on (designs use the fast one)",
    ),
    option(
        "--robust",
        metavar="POSTERIOR.nc",
        default=None,
        help="tune the feedback on the cost averaged over draws of this posterior (default: none)",
    ),
    option(
        "--robust-rig",
        action="store_true",
        help="tune the feedback on the cost averaged over draws of the rig within its tolerance budget "
        "(--tolerance adjusts the budget)",
    ),
    option(
        "--tuning-draws",
        type=count(),
        default=8,
        metavar="N",
        help="draws the feedback is tuned on: of the posterior (--robust), of the rig (--robust-rig)",
    ),
    option("--iterations", type=count(), default=10, metavar="N", help="optimiser steps and tuning rounds"),
    option(
        "--microsteps", type=count(), default=1, metavar="N", help="stepper driver microsteps (1: the full-step driver)"
    ),
)


def add_arguments(parser) -> None:
    """The shared options (no ``--fidelity``, ``--rtol``: designs run the fast configuration at its tolerance,
    ``--evaluate-on`` names the evaluation's), the design's, ``--tolerance``, ``--quiet``."""
    options.shared(parser, NAME, fidelity=False, rtol=False)
    options.add(parser, (*OPTIONS, options.TOLERANCE))
    options.quiet(parser)


def run(args) -> dict:
    """Design on the fast model, evaluate on ``--evaluate-on``, write the figure; the summary, RunFailed where the
    evaluation crossed the membrane pressure limit or failed."""
    if args.robust is not None and not Path(args.robust).is_file():
        raise ValueError(f"--robust {args.robust}: no such file (a posterior's InferenceData, .nc)")
    from growjax import control as gc

    rig_budget(args)  # a bad --tolerance is refused before any work
    data = loader.load(args)
    target = gc.target_from_experiment(data.experiment, args.t_end)
    out = out_dir(args)
    started = note(args, f"control: {args.method} design on the fast model, evaluated on {args.evaluate_on}")
    summary = _design(args, target, data.base(), out)
    note(args, f"control: done in {time.perf_counter() - started:.1f} s")
    summary = {"command": NAME, "data": str(data.path), "fixed_parameters": data.origin, **summary}
    peak, limit = summary.get("peak_pressure_Pa"), summary["pressure_limit_Pa"]
    if summary.get("status") == "pressure_limit" or (peak is not None and peak > limit):
        raise RunFailed(
            f"the design reached the membrane pressure limit ({limit / 1e3:.1f} kPa; peak "
            f"{max(peak or limit, limit) / 1e3:.1f} kPa)",
            summary,
        )
    rmse = summary.get("tracking_rmse_m")
    if rmse is None or not math.isfinite(rmse) or summary.get("status") not in ("ok", None):
        raise RunFailed(f"the evaluation run failed ({summary.get('status')})", summary)
    return summary


def rig_budget(args) -> dict | None:
    """The rig's tolerances the feedback is tuned over: with ``--robust-rig`` the budget (``--tolerance`` on the
    default one); None without it (the rig as it is). ValueError where ``--tolerance`` is given without
    ``--robust-rig``, or the budget is empty."""
    if not args.robust_rig:
        if args.tolerance:
            raise ValueError("--tolerance adjusts the rig's budget that --robust-rig tunes over: add --robust-rig")
        return None
    from growjax.calibration import tolerance as tl
    from growjax.model import params as gp

    budget = options.tolerances_of(args)
    if budget is None:
        budget = tl.default_budget(gp.reference(args.drive))
    if not budget:
        raise ValueError("--robust-rig with --tolerance none: no rig tolerance to draw the rig from")
    return budget


# -- the workflow's call ----------------------------------------------------------------------------------------


def _design(args, target, base, out) -> dict:
    """The design to track ``target`` and its evaluation (`growjax.control.design`)."""
    from growjax import control as gc

    return gc.design_controller(
        target,
        args.drive,
        args.method,
        args.t_end,
        robust=args.robust,
        n_draws=args.tuning_draws,
        iterations=args.iterations,
        microsteps=args.microsteps,
        evaluate_on=args.evaluate_on,
        seed=args.seed,
        figure=out / "control.png",
        base=base,
        tolerances=rig_budget(args),
    )


def _evaluation_line(s: dict) -> str:
    """The evaluation's tracking error and peak pressure; where it stopped at the membrane limit, the limit as its
    peak; where it failed, the peak up to its failure; a tracking error only where the run reached its end."""
    limit, peak = s.get("pressure_limit_Pa"), s.get("peak_pressure_Pa")
    ceilings = f"limit {kpa(limit)}, demand ceiling {kpa(s.get('max_demand_Pa'))}"
    rmse = s.get("tracking_rmse_m")
    reached_end = rmse is not None and math.isfinite(rmse)
    at_limit = s.get("status") == "pressure_limit" or (peak is not None and limit is not None and peak > limit)
    if at_limit:
        peak = max((p for p in (peak, limit) if p is not None), default=None)  # the sensed pressure at the stop
        tracked = f"tracking RMSE {mm(rmse)}" if reached_end else "no tracking RMSE"
        return f"  the evaluation run reached the membrane limit: {tracked}; peak pressure {kpa(peak)} ({ceilings})"
    if s.get("status") in ("ok", None) and reached_end:
        return f"  tracking RMSE {mm(rmse)}; peak pressure {kpa(peak)} ({ceilings})"
    return (
        f"  the evaluation run did not reach its end ({s.get('status')}): no tracking RMSE; peak pressure up to "
        f"its failure {kpa(peak)} ({ceilings})"
    )


def summary_lines(s: dict) -> list[str]:
    """The tracking error, peak pressure, gains and figure."""
    lines = [
        f"control: {data_name(s)}, {s['drive']} drive, {s['method']}, evaluated on the {s['evaluated_on']} "
        "configuration",
        *origin_lines(s["fixed_parameters"]),
        _evaluation_line(s),
    ]
    if s.get("gains"):
        lines.append(
            "  gains: "
            + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in s["gains"].items())
        )
    if s.get("figure"):
        lines.append(f"  wrote {s['figure']}")
    return lines


__all__ = ["HELP", "NAME", "OPTIONS", "PROCESS", "add_arguments", "rig_budget", "run", "summary_lines"]
