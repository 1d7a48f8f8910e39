"""``growjax simulate [DATA]``: one run of the model on an experiment's inputs, against its measured length; writes
trajectory.csv and trajectory.png."""

from __future__ import annotations

import time

import numpy as np

from growjax.cli import loader, options
from growjax.cli._summary import data_name, kpa, mm, origin_lines
from growjax.cli.command import Process, RunFailed, note, out_dir

NAME = "simulate"
HELP = "simulate an experiment against its measured length"
PROCESS = Process(quick_compile=True)


def add_arguments(parser) -> None:
    """The shared options (no ``--seed``: nothing is drawn) and ``--quiet``."""
    options.shared(parser, NAME, seed=False)
    options.quiet(parser)


def run(args) -> dict:
    """Simulate DATA's inputs on ``--fidelity``; the summary, RunFailed where the solver failed or the sensed
    pressure crossed the membrane limit."""
    import growjax as gj
    from growjax.data import experiment as ex
    from growjax.simulation.metrics import length_rmse

    data = loader.load(args)
    exp, params = data.experiment, data.base()
    config = options.make_config(args, args.drive)
    inputs = ex.to_inputs(exp, args.drive, params, config.t0, config.t1)
    ts = exp.time[(exp.time >= config.t0) & (exp.time <= config.t1)]
    ts = np.unique(np.concatenate([[config.t0], ts, [config.t1]]))
    note(args, f"simulate: {config.fidelity} configuration, {config.t0:g}–{config.t1:g} s, compiled then run")
    traj, first, wall = _simulate(params, inputs, config, ts)
    out = out_dir(args)
    series = _write_trajectory(traj, inputs, args.drive, out)
    measured = (exp.time, exp["robot_length_m"]) if "robot_length_m" in exp else None
    summary = {
        "command": NAME,
        "data": str(data.path),
        "drive": args.drive,
        "fidelity": config.fidelity,
        "t_end_s": args.t_end,
        "parameters": data.origin,
        "status": gj.status_name(traj.status),
        "limit_time_s": None if not np.isfinite(float(traj.limit_time)) else float(traj.limit_time),
        "pressure_limit_Pa": float(gj.pressure_limit(params.robot)),
        **_last_sample(traj, float(gj.pressure_limit(params.robot))),
        "solver_steps": int(traj.n_steps),
        "wall_s": wall,
        "first_call_s": first,
        "trajectory_csv": str(out / "trajectory.csv"),
    }
    if measured is not None and summary["status"] == "ok":
        summary["rmse_length_m"] = float(length_rmse(traj, *measured, t_start=config.t0, t_end=config.t1))
    summary["figure"] = str(_figure(traj, summary, series, measured, args.drive, data.path.name, out))
    if summary["status"] == "pressure_limit":
        raise RunFailed(
            f"the sensed pressure crossed the membrane limit ({summary['pressure_limit_Pa'] / 1e3:.1f} kPa) "
            f"at t = {summary['limit_time_s']:.3f} s; the run stopped there",
            summary,
        )
    if summary["status"] != "ok":
        raise RunFailed(f"the solver failed ({summary['status']}) after {summary['solver_steps']} steps", summary)
    return summary


def _status_lines(s: dict) -> list[str]:
    """The run's status with its length and peak pressure: at the end, or at the stop and nothing after it."""
    limit = f"membrane limit {kpa(s['pressure_limit_Pa'])}"
    if s["status"] == "ok":
        return [
            f"  status ok; final length {mm(s['final_length_m'])}; peak pressure {kpa(s['peak_pressure_Pa'])} ({limit})"
        ]
    stop = s.get("stop_time_s")
    at = "" if stop is None else f" at t = {stop:.3f} s"
    if s["status"] == "pressure_limit":
        head = f"  status pressure_limit: the sensed pressure reached the {limit}{at}; the run stopped there"
    else:
        head = f"  status {s['status']}: the solver stopped{at}"
    last = s.get("final_time_s")
    if last is None:
        return [head, "  no sample before the stop"]
    at_stop = stop is not None and abs(last - stop) < 1e-9
    where = "at the stop" if at_stop else f"at t = {last:.3f} s (the last sample before the stop)"
    return [
        head,
        f"  {where}: length {mm(s['final_length_m'])}; peak pressure up to it {kpa(s['peak_pressure_Pa'])}; "
        "nothing simulated after it",
    ]


# -- the workflow's call ----------------------------------------------------------------------------------------


def _simulate(params, inputs, config, ts):
    """(trajectory, first call's wall time s, the second's): the run twice, its compile timed apart. Where the
    first stopped before ``ts``' end, the second saves at its stop too (the first save time after it moved there:
    the same program, and the samples after a stop are NaN either way)."""
    import jax

    import growjax as gj

    start = time.perf_counter()
    traj = jax.block_until_ready(gj.simulate(params, inputs, config, ts=ts))
    first = time.perf_counter() - start
    stop = float(traj.t_final)
    after = np.flatnonzero(ts > stop + 1e-12)
    if after.size and (after[0] == 0 or ts[after[0] - 1] < stop):
        ts = ts.copy()
        ts[after[0]] = stop
    start = time.perf_counter()
    traj = jax.block_until_ready(gj.simulate(params, inputs, config, ts=ts))
    return traj, first, time.perf_counter() - start


def _last_sample(traj, limit: float) -> dict:
    """The summary's last simulated sample: its time, length and the peak sensed pressure up to it (the samples
    after a stop are NaN: nothing after a stop is reported), and where the run stopped before its end. A run
    stopped at the membrane limit ``limit`` (Pa) stopped where the sensed pressure reached it: that is its peak."""
    import growjax as gj

    status = gj.status_name(traj.status)
    length, pressure = np.asarray(traj.length), np.asarray(traj.pressure)
    finite = np.flatnonzero(np.isfinite(length) & np.isfinite(pressure))
    stop = float(traj.t_final) if status != "ok" else None
    if not finite.size:
        return {"final_time_s": None, "final_length_m": None, "peak_pressure_Pa": None, "stop_time_s": stop}
    peak = float(np.max(pressure[finite]))
    return {
        "final_time_s": float(np.asarray(traj.time)[finite[-1]]),
        "final_length_m": float(length[finite[-1]]),
        "peak_pressure_Pa": max(peak, limit) if status == "pressure_limit" else peak,
        "stop_time_s": stop,
    }


# -- files --------------------------------------------------------------------------------------------------------


def _write_trajectory(traj, inputs, drive: str, out) -> dict:
    """trajectory.csv in ``out``: the series (SI) a run of ``drive`` gives, as an experiment file; the series."""
    import jax

    from growjax.data import experiment as ex

    series = {
        "robot_length_m": np.asarray(traj.length),
        "pressure_Pa": np.asarray(traj.pressure),
        "catheter_length_m": np.asarray(jax.vmap(inputs.catheter_length)(traj.time)),
    }
    if drive == "forward":
        series["pressure_demand_Pa"] = np.asarray(traj.pressure_demand)
    else:
        series["desired_length_m"] = np.asarray(jax.vmap(inputs.desired_length)(traj.time))
    series["robot_flow_m3_s"] = np.asarray(traj.robot_flow)
    series["syringe_displacement_m"] = np.asarray(traj.syringe_displacement)
    ex.write_csv(out / "trajectory.csv", traj.time, series)
    return series


def _figure(traj, summary: dict, series: dict, measured, drive: str, name: str, out):
    """trajectory.png in ``out``: the run against the measured length (and the desired length of the stepper)."""
    from growjax.plotting import trajectory_figure

    title = f"{drive} drive on {name}"
    if "rmse_length_m" in summary:
        title += f": length RMSE {1e3 * summary['rmse_length_m']:.2f} mm"
    return trajectory_figure(
        traj,
        out / "trajectory.png",
        measured=measured,
        desired=(np.asarray(traj.time), series["desired_length_m"]) if drive == "inverse" else None,
        title=title,
        pressure_limit=summary["pressure_limit_Pa"],
    )


def summary_lines(s: dict) -> list[str]:
    """The run's status, final length (at its stop, where it stopped), peak pressure, length RMSE, steps and
    files."""
    lines = [
        f"simulate: {data_name(s)}, {s['drive']} drive, {s['fidelity']} configuration, 0–{s['t_end_s']:g} s",
        *origin_lines(s["parameters"]),
        *_status_lines(s),
    ]
    if "rmse_length_m" in s:
        lines.append(f"  length RMSE against the measured length: {mm(s['rmse_length_m'])}")
    lines.append(
        f"  {s['solver_steps']} solver steps, {1e3 * s['wall_s']:.0f} ms after compiling "
        f"({s['first_call_s']:.1f} s first call)"
    )
    lines.append(f"  wrote {s['trajectory_csv']}, {s['figure']}")
    return lines


__all__ = ["HELP", "NAME", "PROCESS", "add_arguments", "run", "summary_lines"]
