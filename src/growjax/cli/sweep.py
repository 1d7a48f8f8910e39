"""``growjax sweep [DATA]``: a Latin-hypercube sweep of parameter sets scored against the measured length, kept
in a store that ``--resume`` completes; writes sweep.csv and sweep.png (and sobol.png with ``--sobol``)."""

from __future__ import annotations

import numpy as np

from growjax.cli import _sweep as cs
from growjax.cli import loader, options
from growjax.cli._summary import data_name, mm, origin_lines, value
from growjax.cli.command import Process, RunFailed, out_dir
from growjax.cli.options import count, listed, option, power_of_two

NAME = "sweep"
HELP = "Latin-hypercube sweep scored against the measured length"
PROCESS = Process(cpu_devices=True)
OPTIONS = (
    option("--sets", type=count(), default=500, metavar="N", help="parameter sets of the Latin hypercube"),
    listed(
        "--range",
        default=[],
        metavar="NAME=LOW:HIGH[:log][,...]",
        help="swept parameters and their ranges, SI units (default: the paper's n, Y, ext box)",
    ),
    option("--sobol", action="store_true", help="also compute Sobol indices of RMSE and final length"),
    option(
        "--sobol-points",
        type=power_of_two,
        default=256,
        metavar="N",
        rare=True,
        help="Saltelli base points of the Sobol indices (a power of 2; runs = N·(d+2))",
    ),
    option(
        "--chunk-size",
        type=count(),
        default=None,
        metavar="N",
        rare=True,
        help="sets per compiled call (default: sized to memory)",
    ),
    option(
        "--resume",
        metavar="DIR",
        default=None,
        help="complete the interrupted sweep kept in DIR (its --out); its options are the recorded ones "
        "(default: a new sweep)",
    ),
    option(
        "--max-chunks",
        type=count(),
        default=None,
        metavar="K",
        rare=True,
        help="stop after K chunks, as an interrupt would (exit 3; complete with --resume) (default: no limit)",
    ),
    option(
        "--distributed",
        action="store_true",
        rare=True,
        help="one process of several (jax.distributed, the cluster detected: SLURM, ...); process 0 writes the results",
    ),
    option(
        "--coordinator",
        metavar="HOST:PORT",
        default=None,
        rare=True,
        help="jax.distributed without a detected cluster: process 0's address (with --num-processes, --process-id) "
        "(default: none)",
    ),
    option(
        "--num-processes",
        type=count(),
        default=None,
        metavar="N",
        rare=True,
        help="processes in all (--coordinator) (default: none)",
    ),
    option(
        "--process-id",
        type=count(0),
        default=None,
        metavar="I",
        rare=True,
        help="this process, 0..N-1 (--coordinator) (default: none)",
    ),
)


def add_arguments(parser) -> None:
    """The shared options, the sweep's, ``--quiet``."""
    options.shared(parser, NAME)
    options.add(parser, OPTIONS)
    options.quiet(parser)


def run(args) -> dict:
    """Start ``jax.distributed`` where asked, sweep (or complete ``--resume``'s sweep), write the table and figure;
    the summary (a worker's: its process index alone), RunFailed where members failed, `Stopped` where it
    stopped before its end."""
    import jax

    from growjax import sweep as sw
    from growjax.data import experiment as ex

    cs.start_distributed(args)
    if args.resume:
        cs.restore(args)
    data = loader.load(args)
    exp, base = data.experiment, data.base()
    dims = tuple(sw.parse_dimension(p, base) for p in args.range) if args.range else sw.paper_box()
    _check_ranges(dims, base)
    config = options.make_config(args, args.drive)
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    measured = (exp.time, exp["robot_length_m"]) if "robot_length_m" in exp else None
    result = _sweep(args, base, inputs, config, dims, measured)
    if jax.process_index() != 0:  # process 0 writes the files and reports
        return {"command": NAME, "process_index": jax.process_index()}
    out = out_dir(args)
    summary = _summary(args, data, config, dims, result, measured is not None, out)
    if args.sobol:
        summary.update(_sobol(args, base, inputs, config, dims, measured, out))
    if summary["n_failed"]:
        reasons = ", ".join(f"{n} {why}" for why, n in summary["failed_reasons"].items())
        raise RunFailed(
            f"{summary['n_failed']} of {args.sets} sweep members failed ({reasons}); see {out / 'sweep.csv'}", summary
        )
    return summary


def _check_ranges(dims, base) -> None:
    """ValueError where a swept range leaves its parameter's physical range (`growjax params`)."""
    from growjax.model import params as gp

    ranges = gp.physical_ranges(base)
    for d in dims:
        lo, hi, unit = ranges.get(d.name, (None, None, ""))
        if lo is not None and (d.low < lo or d.high > hi):
            raise ValueError(
                f"--range {d.name}={d.low:g}:{d.high:g} leaves its physical range {lo:g}–{hi:g} {unit}".rstrip()
            )


def _summary(args, data, config, dims, result, measured: bool, out) -> dict:
    """sweep.csv and sweep.png in ``out``; the summary."""
    import jax

    from growjax.plotting import sweep_figure

    result.write_csv(out / "sweep.csv")
    best = result.best()
    title = f"{args.sets}-set Latin hypercube on {data.path.name}"
    if best is not None and measured:
        title += f": best RMSE {1e3 * best['rmse_length_m']:.2f} mm"
    fig = sweep_figure(result, out / "sweep.png", title=title)
    failed = {}
    for why in result.reasons:
        if why != "ok":
            failed[why] = failed.get(why, 0) + 1
    summary = {
        "command": NAME,
        "data": str(data.path),
        "drive": args.drive,
        "fidelity": config.fidelity,
        "t_end_s": args.t_end,
        "n": args.sets,
        "seed": args.seed,
        "parameters": data.origin,
        "ranges": [{"name": d.name, "low": d.low, "high": d.high, "log": d.log} for d in dims],
        "best": best,
        "n_failed": int(np.sum(result.failed)),
        "failed_reasons": failed,
        "wall_s": result.wall_s,
        "compile_s": result.compile_s,
        "trace_lower_s": result.lower_s,
        "n_devices": result.n_devices,
        "device": str(jax.devices()[0].platform),
        "table_csv": str(out / "sweep.csv"),
        "store": str(cs.store_path(out)),
        "figure": str(fig),
    }
    if jax.process_count() > 1:
        summary["n_processes"] = jax.process_count()
    return summary


# -- the workflow's calls ---------------------------------------------------------------------------------------


def _sweep(args, base, inputs, config, dims, measured):
    """The sweep's result (`growjax.sweep`): a new one into ``--out``'s store, or ``--resume``'s completed;
    `Stopped` where it stopped before its end."""
    import jax

    from growjax import sweep as sw

    leader = jax.process_index() == 0
    progress = not args.quiet and leader
    try:
        if args.resume:
            return sw.resume(
                cs.store_path(args.out), base, inputs, measured, progress=progress, max_chunks=args.max_chunks
            )
        store = cs.prepare_new(args.out) if leader else cs.store_path(args.out)
        return sw.lhs_sweep(
            args.sets,
            base,
            inputs,
            config,
            dims,
            seed=args.seed,
            measured=measured,
            chunk_size=args.chunk_size,
            progress=progress,
            store=store,
            max_chunks=args.max_chunks,
            metadata={"cli": cs.record(args)},
        )
    except (sw.SweepInterrupted, KeyboardInterrupt) as err:
        raise cs.stopped(err, args.out, jax.process_count() > 1) from None


def _sobol(args, base, inputs, config, dims, measured, out) -> dict:
    """The Sobol indices' part of the summary, and sobol.png in ``out``."""
    from growjax import sweep as sw
    from growjax.plotting import sobol_figure

    sob = sw.sobol_indices(
        dims,
        base,
        inputs,
        config,
        n_base=args.sobol_points,
        seed=args.seed,
        measured=measured,
        chunk_size=args.chunk_size,
        progress=not args.quiet,
    )
    return {
        "sobol": {
            "names": sob["names"],
            "n_runs": sob["n_runs"],
            "indices": sob["indices"],
            "wall_s": sob["sweep"].wall_s,
        },
        "sobol_figure": str(sobol_figure(sob, out / "sobol.png", title=f"Sobol indices ({sob['n_runs']} runs)")),
    }


def summary_lines(s: dict) -> list[str]:
    """The sweep's ranges, failures, timing, best set, Sobol indices and files."""
    ranges = ", ".join(f"{r['name']} {r['low']:g}–{r['high']:g}" + (" (log)" if r["log"] else "") for r in s["ranges"])
    lines = [
        f"sweep: {data_name(s)}, {s['n']} sets (seed {s['seed']}) over {ranges}",
        *origin_lines(s["parameters"]),
        (
            f"  {s['n_failed']} failed; sweep {s['wall_s']:.2f} s after {s['compile_s']:.1f} s compiling, "
            f"{s['n_devices']} {s['device']} devices"
        ),
    ]
    if s.get("best"):
        best = ", ".join(f"{k} = {value(k, v)}" for k, v in s["best"]["parameters"].items())
        among = f" of the {s['n'] - s['n_failed']} that ran to their end" if s["n_failed"] else ""
        lines.append(f"  best{among}: {best}; length RMSE {mm(s['best']['rmse_length_m'])}")
    elif s["n_failed"] == s["n"]:
        lines.append("  no set ran to its end: no best")
    for output, table in s.get("sobol", {}).get("indices", {}).items():
        if "S1" in table:
            shown = ", ".join(
                f"{n.split('.')[-1]} {a:.2f}/{b:.2f}" for n, a, b in zip(s["sobol"]["names"], table["S1"], table["ST"])
            )
            lines.append(f"  Sobol S1/ST of {output}: {shown}")
    lines.append(f"  wrote {s['table_csv']}, {s['figure']}")
    return lines


__all__ = ["HELP", "NAME", "OPTIONS", "PROCESS", "add_arguments", "run", "summary_lines"]
