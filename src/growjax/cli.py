"""Command line: ``growjax simulate [DATA] ...`` and ``growjax sweep [DATA] ...`` (``growjax --help``)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from growjax._data import default_data_path


def _enable_compile_cache():
    import jax

    cache = os.environ.get("GROWJAX_CACHE_DIR", str(Path.home() / ".cache" / "growjax" / "jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def parse_param(text: str):
    """``NAME=VALUE`` → (name, float); ValueError with the problem named."""
    if "=" not in text:
        raise ValueError(f"--param expects NAME=VALUE, got {text!r}")
    name, value = text.split("=", 1)
    try:
        return name.strip(), float(value)
    except ValueError:
        raise ValueError(f"--param {name}: {value!r} is not a number") from None


def make_config(args, drive: str = "forward", **extra):
    """The :class:`growjax.Config` named by the common options (--fidelity, --rtol, --t-end)."""
    import growjax as gj

    return gj.Config(fidelity=args.fidelity, drive=drive, t1=args.t_end, rtol=args.rtol, atol=args.rtol, **extra)


def simulate_command(args) -> dict:
    import jax

    import growjax as gj
    from growjax import experiment as ex
    from growjax.metrics import length_rmse
    from growjax.plotting import trajectory_figure

    data = Path(args.data) if args.data else default_data_path()
    exp = ex.read(data).window(args.t_end + 1e-9)
    params = gj.reference(args.drive)
    overrides = dict(parse_param(p) for p in args.param)
    params = gj.replace(params, **overrides) if overrides else params
    gj.validate(params)
    config = make_config(args, args.drive)
    inputs = ex.to_inputs(exp, args.drive, params, config.t0, config.t1)
    ts = exp.time[(exp.time >= config.t0) & (exp.time <= config.t1)]
    ts = np.unique(np.concatenate([[config.t0], ts, [config.t1]]))

    start = time.perf_counter()
    traj = jax.block_until_ready(gj.simulate(params, inputs, config, ts=ts))
    first = time.perf_counter() - start
    start = time.perf_counter()
    traj = jax.block_until_ready(gj.simulate(params, inputs, config, ts=ts))
    wall = time.perf_counter() - start

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    series = {
        "robot_length_m": np.asarray(traj.length),
        "pressure_Pa": np.asarray(traj.pressure),
        "catheter_length_m": np.asarray(jax.vmap(inputs.catheter_length)(traj.time)),
    }
    if args.drive == "forward":
        series["pressure_demand_Pa"] = np.asarray(traj.pressure_demand)
    else:
        series["desired_length_m"] = np.asarray(jax.vmap(inputs.desired_length)(traj.time))
    series["robot_flow_m3_s"] = np.asarray(traj.robot_flow)
    series["syringe_displacement_m"] = np.asarray(traj.syringe_displacement)
    ex.write_csv(out / "trajectory.csv", traj.time, series)

    measured = (exp.time, exp["robot_length_m"]) if "robot_length_m" in exp else None
    summary = {
        "data": str(data),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "status": gj.status_name(traj.status),
        "limit_time_s": None if not np.isfinite(float(traj.limit_time)) else float(traj.limit_time),
        "pressure_limit_Pa": float(gj.pressure_limit(params.robot)),
        "final_length_m": float(np.asarray(traj.length)[np.isfinite(traj.length)][-1]),
        "peak_pressure_Pa": float(np.nanmax(traj.pressure)),
        "solver_steps": int(traj.n_steps),
        "wall_s": wall,
        "first_call_s": first,
        "overrides": overrides,
        "trajectory_csv": str(out / "trajectory.csv"),
    }
    if measured is not None:
        rmse = length_rmse(traj, *measured, t_start=config.t0, t_end=config.t1)
        summary["rmse_length_m"] = float(rmse)
    fig = trajectory_figure(
        traj,
        out / "trajectory.png",
        measured=measured,
        desired=(np.asarray(traj.time), series["desired_length_m"]) if args.drive == "inverse" else None,
        title=f"{args.drive} drive on {data.name}"
        + (f": length RMSE {1e3 * summary['rmse_length_m']:.2f} mm" if measured is not None else ""),
        pressure_limit=summary["pressure_limit_Pa"],
    )
    summary["figure"] = str(fig)
    return summary


def _use_all_cpu_cores(at_least: int = 1):
    """Expose every CPU core (and at least ``at_least``) as a JAX device, so that sweeps shard across them and
    NUTS chains run one per device (GROWJAX_CPU_DEVICES overrides)."""
    import jax

    wanted = os.environ.get("GROWJAX_CPU_DEVICES")
    n = int(wanted) if wanted else max(os.cpu_count() or 1, at_least)
    if "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""):
        return
    try:
        jax.config.update("jax_num_cpu_devices", n)
    except (AttributeError, RuntimeError):
        pass  # older JAX, or the backend is already initialised


def sweep_command(args) -> dict:
    import jax

    import growjax as gj
    from growjax import experiment as ex
    from growjax import sweep as sw
    from growjax.plotting import sobol_figure, sweep_figure

    data = Path(args.data) if args.data else default_data_path()
    exp = ex.read(data).window(args.t_end + 1e-9)
    base = gj.reference("forward")
    dims = tuple(sw.parse_dimension(p, base) for p in args.param) if args.param else sw.paper_box()
    config = make_config(args)
    inputs = ex.to_inputs(exp, "forward", base, config.t0, config.t1)
    measured = (exp.time, exp["robot_length_m"]) if "robot_length_m" in exp else None
    result = sw.lhs_sweep(args.n, base, inputs, config, dims, seed=args.seed, measured=measured,
                          chunk_size=args.chunk_size, progress=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result.write_csv(out / "sweep.csv")
    best = result.best()
    title = f"{args.n}-set Latin hypercube on {data.name}"
    if best is not None and measured is not None:
        title += f": best RMSE {1e3 * best['rmse_length_m']:.2f} mm"
    fig = sweep_figure(result, out / "sweep.png", title=title)
    failed = {}
    for why in result.reasons:
        if why != "ok":
            failed[why] = failed.get(why, 0) + 1
    summary = {
        "data": str(data),
        "fidelity": args.fidelity,
        "t_end_s": args.t_end,
        "n": args.n,
        "seed": args.seed,
        "parameters": [{"name": d.name, "low": d.low, "high": d.high, "log": d.log} for d in dims],
        "best": best,
        "n_failed": int(np.sum(result.failed)),
        "failed_reasons": failed,
        "wall_s": result.wall_s,
        "compile_s": result.compile_s,
        "trace_lower_s": result.lower_s,
        "n_devices": result.n_devices,
        "device": str(jax.devices()[0].platform),
        "table_csv": str(out / "sweep.csv"),
        "figure": str(fig),
    }
    if args.sobol:
        sob = sw.sobol_indices(dims, base, inputs, config, n_base=args.sobol_n, seed=args.seed, measured=measured,
                               chunk_size=args.chunk_size, progress=True)
        summary["sobol"] = {"names": sob["names"], "n_runs": sob["n_runs"], "indices": sob["indices"],
                            "wall_s": sob["sweep"].wall_s}
        summary["sobol_figure"] = str(sobol_figure(sob, out / "sobol.png", title=f"Sobol indices ({sob['n_runs']} runs)"))
    return summary


def fit_command(args) -> dict:
    import growjax as gj
    from growjax import experiment as ex
    from growjax import fit as gf
    from growjax.plotting import trajectory_figure

    data = Path(args.data) if args.data else default_data_path()
    exp = ex.read(data).window(args.t_end + 1e-9)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to fit")
    base = gj.reference(args.drive)
    config = make_config(args, args.drive, adjoint="forward")
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    pressure = exp["pressure_Pa"] if "pressure_Pa" in exp else None  # noqa: SIM401 (Experiment is not a dict)
    result = gf.fit(exp.time, exp["robot_length_m"], inputs, free=args.free or ["Y"], base=base, config=config,
                    pressure=pressure, n_starts=args.starts, seed=args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fitted = gj.replace(base, **result.estimate)
    traj = gj.simulate(fitted, inputs, config)
    fig = trajectory_figure(traj, out / "fit.png", measured=(exp.time, exp["robot_length_m"]),
                            title=f"fit of {', '.join(result.names)}: RMSE {1e3 * result.rmse_length_m:.2f} mm")
    summary = {"data": str(data), "drive": args.drive, "t_end_s": args.t_end, "fidelity": config.fidelity,
               **result.summary(), "figure": str(fig)}
    return summary


def posterior_command(args) -> dict:
    import growjax as gj
    from growjax import experiment as ex
    from growjax import posterior as gpost

    data = Path(args.data) if args.data else default_data_path()
    exp = ex.read(data).window(args.t_end + 1e-9)
    base = gj.reference("forward", growth_law=args.law)
    config = make_config(args, adjoint="forward")
    inputs = ex.to_inputs(exp, "forward", base, config.t0, config.t1)
    priors = gpost.paper_priors() if args.law == "reference" else gpost.lockhart_priors()
    res = gpost.sample(exp.time, exp["robot_length_m"], inputs, base, config, priors=priors, chains=args.chains,
                       warmup=args.warmup, samples=args.samples, seed=args.seed, progress=True,
                       emulate=args.emulate)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res.idata.to_netcdf(str(out / "posterior.nc"))
    return {"data": str(data), "t_end_s": args.t_end, "growth_law": args.law, **res.summary,
            "inference_data": str(out / "posterior.nc")}


def discover_command(args) -> dict:
    import growjax as gj
    from growjax import discover as gd
    from growjax import experiment as ex
    from growjax.plotting import discovery_figure

    data = Path(args.data) if args.data else default_data_path()
    exp = ex.read(data).window(args.t_end + 1e-9)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to explain")
    config = make_config(args, args.drive, adjoint="forward")
    base = gj.reference(args.drive)
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    keep = (exp.time >= config.t0) & (exp.time <= config.t1)
    res = gd.discover(exp.time[keep], exp["robot_length_m"][keep], inputs, base=base, config=config,
                      candidates=args.candidates or None, progress=True, workers=args.workers)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    figure = discovery_figure(res, out / "discover.png", title=f"{data.name}: {res.effect}")
    print(gd.summary_text(res), file=sys.stderr)
    return {"data": str(data), "drive": args.drive, "t_end_s": args.t_end, **res.report(), "figure": str(figure)}


def _control_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``growjax control DATA``."""
    parser.add_argument("data", nargs="?", help="experiment CSV (or folder); target: desired_length_m, else robot_length_m")
    parser.add_argument("--drive", choices=["forward", "inverse"], default="forward")
    parser.add_argument("--method", choices=["open-loop", "feedback", "mpc"], default="feedback")
    parser.add_argument("--robust", metavar="POSTERIOR.nc", help="tune on the cost averaged over posterior draws")
    parser.add_argument("--draws", type=int, default=8, help="posterior draws to tune on (--robust; default 8)")
    parser.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    parser.add_argument("--iterations", type=int, default=10, help="optimiser / tuning iterations (default 10)")
    parser.add_argument("--microsteps", type=int, default=1,
                        help="stepper driver microsteps (1: the shipped full-step driver)")
    parser.add_argument("--evaluate", choices=["fast", "reference"], default="reference",
                        help="configuration the tracking RMSE is evaluated on (default reference)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="out", help="output folder (control.png)")
    parser.add_argument("--json", help="also write the JSON summary to this file")


def control_command(args) -> dict:
    """Run ``growjax control``: design on the fast model, evaluate on ``--evaluate``, write a figure, return JSON."""
    from growjax import experiment as ex
    from growjax.control import design, target_from_experiment

    data = Path(args.data) if args.data else default_data_path()
    target = target_from_experiment(ex.read(data), args.t_end)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = design(target, args.drive, args.method, args.t_end, robust=args.robust, n_draws=args.draws,
                     iterations=args.iterations, microsteps=args.microsteps, evaluate_on=args.evaluate,
                     seed=args.seed, figure=out / "control.png")
    return {"data": str(data), **summary}


def build_parser():
    parser = argparse.ArgumentParser(prog="growjax", description="MAMMOBOT growing-robot simulator")
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="simulate an experiment and compare with its measured length")
    sim.add_argument("data", nargs="?", help="experiment CSV (or folder with kings_ts.mat, lin_c_ts.mat); default: shipped synthetic data")
    sim.add_argument("--drive", choices=["forward", "inverse"], default="forward")
    sim.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    sim.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="override a parameter (SI units), e.g. Y=8000")
    sim.add_argument("--out", default="out", help="output folder (trajectory.csv, trajectory.png)")
    sim.add_argument("--json", help="also write the JSON summary to this file")

    swp = sub.add_parser("sweep", help="Latin-hypercube parameter sweep scored against the measured length")
    swp.add_argument("data", nargs="?", help="experiment CSV or folder (default: shipped synthetic data)")
    swp.add_argument("--n", type=int, default=500, help="number of parameter sets (default 500)")
    swp.add_argument("--param", action="append", default=[], metavar="NAME=LOW:HIGH[:log]",
                     help="swept parameter and range, SI units (repeat); default the paper's n, Y, ext box")
    swp.add_argument("--seed", type=int, default=0, help="seed of the design (default 0)")
    swp.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    swp.add_argument("--sobol", action="store_true", help="also compute Sobol indices of RMSE and final length")
    swp.add_argument("--sobol-n", type=int, default=256, help="Saltelli base points (power of 2; runs = N·(d+2))")
    swp.add_argument("--chunk-size", type=int, default=None, help="sets per compiled call (default: memory-sized)")
    swp.add_argument("--out", default="out", help="output folder (sweep.csv, sweep.png, sobol.png)")
    swp.add_argument("--json", help="also write the JSON summary to this file")

    fit = sub.add_parser("fit", help="least-squares fit of parameters to the measured length (and pressure)")
    fit.add_argument("data", nargs="?", help="experiment CSV or folder (default: shipped synthetic data)")
    fit.add_argument("--drive", choices=["forward", "inverse"], default="forward")
    fit.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    fit.add_argument("--free", action="append", default=[], metavar="NAME", help="parameter to fit (repeat; default Y)")
    fit.add_argument("--starts", type=int, default=3, help="multi-start count, from the best LHS sets (default 3)")
    fit.add_argument("--seed", type=int, default=0)
    fit.add_argument("--out", default="out", help="output folder (fit.png)")
    fit.add_argument("--json", help="also write the JSON summary to this file")

    post = sub.add_parser("posterior", help="NUTS posterior of Y, ext, n (or Y, phi_L, n_L) and the noise scale")
    post.add_argument("data", nargs="?", help="experiment CSV or folder (default: shipped synthetic data)")
    post.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    post.add_argument("--law", choices=["reference", "lockhart"], default="reference",
                      help="growth law: the published velocity term (default) or Lockhart's")
    post.add_argument("--emulate", action="store_true",
                      help="sample through a validated tensor-grid emulator instead of the model itself (worth it when "
                           "the data leave directions flat, as ext and n of the published law: NUTS then runs to its "
                           "maximum tree depth, and each gradient through the model costs ~0.1 s)")
    post.add_argument("--chains", type=int, default=4)
    post.add_argument("--warmup", type=int, default=500)
    post.add_argument("--samples", type=int, default=500)
    post.add_argument("--seed", type=int, default=0)
    post.add_argument("--out", default="out", help="output folder (posterior.nc)")
    post.add_argument("--json", help="also write the JSON summary to this file")
    dis = sub.add_parser("discover", help="find the physical effect the base model misses (catalogue of effects)")
    dis.add_argument("data", nargs="?", help="experiment CSV or folder (default: shipped synthetic data)")
    dis.add_argument("--drive", choices=["forward", "inverse"], default="forward")
    dis.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    dis.add_argument("--candidates", nargs="+", metavar="NAME", help="catalogue effects to test (default: all)")
    dis.add_argument("--workers", type=int, help="fits run at a time (default: one per CPU core)")
    dis.add_argument("--out", default="out", help="output folder (discover.png)")
    dis.add_argument("--json", help="also write the JSON report to this file")

    ctl = sub.add_parser("control", help="length control design: open-loop profile, feedback, MPC")
    _control_arguments(ctl)
    for command in (sim, swp, fit, post, dis):
        command.add_argument("--fidelity", choices=["fast", "reference"], default="fast",
                             help="fast configuration (default) or the reference network (slow; for checks)")
        command.add_argument("--rtol", type=float, default=None,
                             help="solver tolerance on scaled states (default: 1e-4 fast, 1e-6 reference)")
    return parser


def main(argv=None) -> int:
    import matplotlib

    matplotlib.use("Agg")  # the commands write figures to files
    args = build_parser().parse_args(argv)
    _enable_compile_cache()
    if args.command in ("simulate", "fit") and args.fidelity == "fast":  # compile-bound: XLA's quicker emitters
        from growjax import xla_flags

        xla_flags.apply_quick_compile()
    from growjax.experiment import ExperimentError

    try:
        if args.command == "sweep":
            _use_all_cpu_cores()
            summary = sweep_command(args)
        elif args.command == "fit":
            summary = fit_command(args)
        elif args.command == "posterior":
            _use_all_cpu_cores(at_least=args.chains)  # chains in parallel, one per device
            if not args.emulate:  # thousands of gradients through the solver: its loop compiled whole
                from growjax import xla_flags

                xla_flags.apply()
            summary = posterior_command(args)
        elif args.command == "discover":
            summary = discover_command(args)
        elif args.command == "control":
            summary = control_command(args)
        else:
            summary = simulate_command(args)
    except (ExperimentError, ValueError) as err:
        print(f"growjax: error: {err}", file=sys.stderr)
        return 2
    text = json.dumps(summary, indent=2, default=str)
    print(text)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(text + "\n")
    return 0 if summary.get("status") != "solver_failed" else 1


if __name__ == "__main__":
    sys.exit(main())
