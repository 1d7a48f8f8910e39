"""Command line: ``growjax simulate [DATA] ...`` (``growjax --help``)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


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


def default_data_path() -> Path:
    """The synthetic experiment shipped with the package."""
    from importlib import resources

    return Path(str(resources.files("growjax") / "datasets" / "synthetic_forward.csv"))


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
    config = gj.Config(drive=args.drive, t1=args.t_end, rtol=args.rtol, atol=args.rtol)
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


def build_parser():
    parser = argparse.ArgumentParser(prog="growjax", description="MAMMOBOT growing-robot simulator")
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="simulate an experiment and compare with its measured length")
    sim.add_argument("data", nargs="?", help="experiment CSV (or folder with kings_ts.mat, lin_c_ts.mat); default: shipped synthetic data")
    sim.add_argument("--drive", choices=["forward", "inverse"], default="forward")
    sim.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    sim.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="override a parameter (SI units), e.g. Y=8000")
    sim.add_argument("--rtol", type=float, default=1e-6, help="solver tolerance on scaled states")
    sim.add_argument("--out", default="out", help="output folder (trajectory.csv, trajectory.png)")
    sim.add_argument("--json", help="also write the JSON summary to this file")
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    _enable_compile_cache()
    from growjax.experiment import ExperimentError

    try:
        summary = simulate_command(args)
    except (ExperimentError, ValueError) as err:
        print(f"growjax: error: {err}", file=sys.stderr)
        return 2
    text = json.dumps(summary, indent=2)
    print(text)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(text + "\n")
    return 0 if summary["status"] != "solver_failed" else 1


if __name__ == "__main__":
    sys.exit(main())
