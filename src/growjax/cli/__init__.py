"""Command line: ``growjax COMMAND [DATA] [options]`` (``growjax --help``, ``growjax COMMAND --help``).

Every workflow command takes the same shared options (``--drive``, ``--param``, ``--fidelity``, ``--rtol``,
``--seed``, ``--t-end``, ``--out``, ``--json``), prints a short summary in mm and kPa, and exits with status 0 when
its runs succeeded, 1 when a run failed (the reason on stderr) and 2 for a bad option or file. A sweep
stopped before its end (its chunks kept for ``growjax sweep --resume DIR``) exits with 128 + the signal's
number (130 for SIGINT, 143 for SIGTERM), or 3 where ``--max-chunks`` stopped it. Progress goes to stderr:
bars on a terminal, a line every ~10 % elsewhere, none with ``--quiet``.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from growjax.cli._parser import BAD_INPUT, build_parser, scored_window, tolerances_of
from growjax.cli._summary import summary_lines
from growjax.data.datasets import default_data_path

OK, RUN_FAILED = 0, 1  # exit statuses (BAD_INPUT, 2, as the parser's)


class RunFailed(Exception):
    """A run finished but failed (solver failure, failed sweep member, fit not converged, limit crossed)."""

    def __init__(self, reason: str, summary: dict):
        super().__init__(reason)
        self.summary = summary


def _enable_compile_cache():
    import jax

    cache = os.environ.get("GROWJAX_CACHE_DIR", str(Path.home() / ".cache" / "growjax" / "jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def _use_all_cpu_cores(at_least: int = 1):
    """Expose every CPU core (and at least ``at_least``) as a JAX device, so that sweeps shard across them, NUTS
    chains run one per device and a set's runs spread over them (GROWJAX_CPU_DEVICES overrides)."""
    import jax

    wanted = os.environ.get("GROWJAX_CPU_DEVICES")
    n = int(wanted) if wanted else max(os.cpu_count() or 1, at_least)
    if "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""):
        return
    try:
        jax.config.update("jax_num_cpu_devices", n)
    except (AttributeError, RuntimeError):
        pass  # older JAX, or the backend is already initialised


# -- parsing helpers --------------------------------------------------------------------------------------------


def parse_param(text: str):
    """``NAME=VALUE`` → (name, float); ValueError with the problem named."""
    if "=" not in text:
        raise ValueError(f"--param expects NAME=VALUE, got {text!r}")
    name, value = text.split("=", 1)
    try:
        return name.strip(), float(value)
    except ValueError:
        raise ValueError(f"--param {name}: {value!r} is not a number") from None


def recorded_parameters(data: Path) -> dict:
    """Parameter values recorded in a JSON file beside ``data`` (``X.json`` beside ``X.csv``), under ``"truth"`` or
    ``"parameters"`` ({name: value}, SI units); {} when there is none."""
    beside = data.with_suffix(".json") if data.suffix else None
    if beside is None or not beside.is_file():
        return {}
    try:
        record = json.loads(beside.read_text())
    except (OSError, ValueError):
        return {}
    values = record.get("truth", record.get("parameters")) if isinstance(record, dict) else None
    if not isinstance(values, dict):
        return {}
    return {k: float(v) for k, v in values.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def data_path(data: str | None, data_dir: str | None = None) -> Path:
    """The experiment a command reads: a path, a named public data set (``mammobot``: :func:`growjax.data.datasets.fetch`,
    from ``data_dir`` where given), or the shipped synthetic experiment."""
    from growjax.data import datasets

    if data is not None and (Path(data).exists() or data not in datasets.NAMES):
        if data_dir is not None:
            raise ValueError(f"--data-dir applies to a named data set ({', '.join(datasets.NAMES)}), not to {data}")
        return Path(data)
    if data is None:
        if data_dir is not None:
            raise ValueError(f"--data-dir applies to a named data set: name it ({', '.join(datasets.NAMES)})")
        return default_data_path()
    return datasets.fetch(data, data_dir=data_dir)


def _setup(args, drive: str, growth_law: str = "reference"):
    """(data path, experiment, parameters, what they came from) for a workflow command."""
    import growjax as gj
    from growjax.data import experiment as ex

    data = data_path(args.data, args.data_dir)
    exp = _in_window(args, ex.read(data, catheter=args.catheter), data)
    params = gj.reference(drive, growth_law=growth_law)
    recorded = recorded_parameters(data)
    fixed = dict(parse_param(p) for p in args.param)
    values = {**recorded, **fixed}
    if values:
        params = gj.replace(params, **values)
    gj.validate(params)
    origin = {"recorded_beside_data": {k: v for k, v in recorded.items() if k not in fixed}, "fixed": fixed}
    return data, exp, params, origin


def _fit_set(args, paths) -> dict:
    """``growjax fit A.csv B.csv …`` or ``growjax fit SET.toml``: the experiments fitted jointly."""
    import growjax as gj
    from growjax.calibration import joint
    from growjax.data import experiment as ex
    from growjax.data import sets as xs
    from growjax.plotting import set_figure

    config = make_config(args, args.drive, adjoint="forward")
    exps = _read_set(args, paths, config)
    fixed = dict(parse_param(p) for p in args.param)
    free = args.free or ["Y@robot"]
    scopes = [xs.Scope.parse(f, exps.runs[0].base()) for f in free]  # a bad scope is refused before any work
    started = _progress_note(args, f"fit: {', '.join(free)} over {len(exps)} experiments from {args.starts} starts")
    result = joint.fit_set(
        exps,
        free=scopes,
        config=config,
        n_starts=args.starts,
        seed=args.seed,
        discrepancy=args.discrepancy,
        tolerances=tolerances_of(args),
        rig=args.rig,
        rig_errors=args.rig_errors,
        rig_tangents=args.rig_tangents,
    )
    _progress_note(args, f"fit: done in {time.perf_counter() - started:.1f} s")
    traces = []
    for run, rec in zip(exps, result.runs):
        values = {
            lab.split("@")[0]: v
            for lab, v in result.estimate.items()
            if "@" not in lab or lab.split("@", 1)[1] in (run.robot, run.rig, run.name)
        }
        rig_values = {
            k: gj.get(run.base(), k) * math.exp(b)
            for k, b in result.rig_offset.get(run.rig if args.rig_errors == "shared" else run.name, {}).items()
        }
        base = gj.replace(run.base(), **rig_values, **values)
        cfg = config.replace(drive=run.drive)
        traj = gj.simulate(base, ex.to_inputs(run.experiment, run.drive, base, cfg.t0, cfg.t1), cfg)
        traces.append((run.name, traj, (run.times, run.length)))
    out = _out(args)
    fig = set_figure(traces, out / "fit.png")
    summary = {
        "command": "fit",
        "data": [str(p) for p in paths],
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fidelity": config.fidelity,
        "free": list(free),
        "fixed_parameters": {"fixed": fixed},
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


def _read_set(args, paths, config):
    """The experiment set of ``paths`` (one TOML manifest, or several files: one robot on one rig), with the
    values recorded beside each file and ``--param`` fixed."""
    import dataclasses

    import growjax as gj
    from growjax.data import sets as xs

    fixed = dict(parse_param(p) for p in args.param)
    if len(paths) == 1:
        exps = xs.ExperimentSet.from_manifest(paths[0], catheter=args.catheter)
    else:
        window = (args.t_start if args.t_start is not None else config.t0, config.t1)
        exps = xs.ExperimentSet.from_files(paths, drive=args.drive, window=window, catheter=args.catheter)
        exps = xs.ExperimentSet(
            tuple(
                dataclasses.replace(r, parameters={**recorded_parameters(Path(p)), **r.parameters})
                for r, p in zip(exps, paths)
            )
        )
    if fixed:
        exps = xs.ExperimentSet(tuple(dataclasses.replace(r, parameters={**r.parameters, **fixed}) for r in exps))
    for run in exps:
        gj.validate(run.base())
    return exps


def _population(args, paths) -> dict:
    """``growjax posterior SET.toml --hierarchical NAME``: the joint fit of the set, then the population of its
    robots' NAME, and the predictive for a new robot of the same build."""
    from growjax.calibration import joint
    from growjax.data import experiment as ex
    from growjax.data import sets as xs
    from growjax.model.params import resolve_name
    from growjax.plotting import population_figure
    from growjax.posterior import population as pop

    config = make_config(args, args.drive, adjoint="forward")
    exps = _read_set(args, paths, config)
    base = exps.runs[0].base()
    name = resolve_name(base, args.hierarchical)
    if len(exps.robots) < 2:
        raise ValueError(
            f"--hierarchical needs experiments of two or more robots, got robot {exps.robots[0]!r}: "
            "name each experiment's robot in a manifest"
        )
    started = _progress_note(args, f"posterior: joint fit of {name}@robot over {len(exps)} experiments")
    fit = joint.fit_set(
        exps,
        free=[f"{name}@robot"],
        config=config,
        seed=args.seed,
        discrepancy=args.discrepancy,
        tolerances=tolerances_of(args),
    )
    if fit.status != "converged":
        raise RunFailed(f"the joint fit did not converge ({fit.status})", {"command": "posterior", **fit.summary()})
    _progress_note(args, f"posterior: joint fit done in {time.perf_counter() - started:.1f} s; NUTS on the population")
    post = pop.sample(fit, name, chains=args.chains, warmup=args.warmup, samples=args.samples, seed=args.seed)
    if args.predict:
        new = ex.read(Path(args.predict), catheter=args.catheter)
        run = xs.Run(
            "new robot",
            new,
            drive=exps.runs[0].drive,
            robot="new robot",
            rig=exps.runs[0].rig,
            parameters=exps.runs[0].parameters,
        )
    else:
        run = exps.runs[0]
    band = pop.predict_new_robot(post, run, config, draws=400, seed=args.seed)
    out = _out(args)
    nc = pop.save(post, out / "population.nc")
    measured = (run.times, run.length) if "robot_length_m" in run.experiment else None
    fig = population_figure(post, band, out / "population.png", measured=measured)
    summary = {
        "command": "posterior",
        "hierarchical": name,
        "data": [str(p) for p in paths],
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fidelity": config.fidelity,
        "chains": args.chains,
        "warmup": args.warmup,
        "samples": args.samples,
        **post.summary(),
        "joint_fit": fit.summary(),
        "new_robot": {
            "input": args.predict or run.name,
            "median_final_length_m": float(band["median"][-1]),
            "band_90_final_length_m": [float(band["lower"][-1]), float(band["upper"][-1])],
            "median_band_width_m": float(np.median(band["upper"] - band["lower"])),
            "failed_draws": band["failed"],
        },
        "wall_s": time.perf_counter() - started,
        "posterior_file": str(nc),
        "figure": str(fig),
    }
    rhat = post.diagnostics["mu"]["r_hat"]
    if args.chains > 1 and (rhat is None or not math.isfinite(rhat) or rhat > 1.1):
        raise RunFailed(f"the chains did not mix (R-hat of mu {rhat}); run more --warmup and --samples", summary)
    return summary


def _in_window(args, exp, data: Path):
    """The samples of ``exp`` in the simulated window [t0, --t-end]. A window that runs past the data's end is
    shrunk to it (``args.t_end`` set, a one-line note on stderr); ExperimentError naming both spans where the
    data and the window do not overlap."""
    import growjax as gj
    from growjax.data.experiment import ExperimentError

    t0, t1 = gj.Config().t0, args.t_end
    first, last = float(exp.time[0]), float(exp.time[-1])
    spans = f"{data} holds data over {first:g}–{last:g} s and the simulated window is {t0:g}–{t1:g} s (--t-end)"
    inside = exp.window(t1 + 1e-9)
    if first > t1 or last <= t0:
        raise ExperimentError(f"{spans}: they do not overlap")
    if inside.time.size < 2:
        raise ExperimentError(f"{spans}: only one sample lies in the window")
    if last < t1 - 1e-9:
        print(f"growjax {args.command}: note: {spans}: the window is shrunk to {t0:g}–{last:g} s", file=sys.stderr)
        args.t_end = last
    return inside


def make_config(args, drive: str = "forward", **extra):
    """The :class:`growjax.Config` named by the shared options (--fidelity, --rtol, --t-end)."""
    import growjax as gj

    return gj.Config(fidelity=args.fidelity, drive=drive, t1=args.t_end, rtol=args.rtol, atol=args.rtol, **extra)


def _out(args) -> Path:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _progress_note(args, text: str) -> float:
    """One line of progress on stderr (none with ``--quiet``); the time, s (``time.perf_counter``)."""
    from growjax import _progress

    _progress.note(text, not args.quiet)
    return time.perf_counter()


# -- commands ---------------------------------------------------------------------------------------------------


def simulate_command(args) -> dict:
    import jax

    import growjax as gj
    from growjax.data import experiment as ex
    from growjax.plotting import trajectory_figure
    from growjax.simulation.metrics import length_rmse

    data, exp, params, origin = _setup(args, args.drive)
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

    out = _out(args)
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
    finite = np.isfinite(np.asarray(traj.length))
    summary = {
        "command": "simulate",
        "data": str(data),
        "drive": args.drive,
        "fidelity": config.fidelity,
        "t_end_s": args.t_end,
        "parameters": origin,
        "status": gj.status_name(traj.status),
        "limit_time_s": None if not np.isfinite(float(traj.limit_time)) else float(traj.limit_time),
        "pressure_limit_Pa": float(gj.pressure_limit(params.robot)),
        "final_length_m": float(np.asarray(traj.length)[finite][-1]) if np.any(finite) else None,
        "peak_pressure_Pa": float(np.nanmax(traj.pressure)) if np.any(np.isfinite(traj.pressure)) else None,
        "solver_steps": int(traj.n_steps),
        "wall_s": wall,
        "first_call_s": first,
        "trajectory_csv": str(out / "trajectory.csv"),
    }
    if measured is not None and summary["status"] == "ok":
        summary["rmse_length_m"] = float(length_rmse(traj, *measured, t_start=config.t0, t_end=config.t1))
    title = f"{args.drive} drive on {data.name}"
    if "rmse_length_m" in summary:
        title += f": length RMSE {1e3 * summary['rmse_length_m']:.2f} mm"
    summary["figure"] = str(
        trajectory_figure(
            traj,
            out / "trajectory.png",
            measured=measured,
            desired=(np.asarray(traj.time), series["desired_length_m"]) if args.drive == "inverse" else None,
            title=title,
            pressure_limit=summary["pressure_limit_Pa"],
        )
    )
    if summary["status"] == "pressure_limit":
        raise RunFailed(
            f"the sensed pressure crossed the membrane limit ({summary['pressure_limit_Pa'] / 1e3:.1f} kPa) "
            f"at t = {summary['limit_time_s']:.3f} s; the run stopped there",
            summary,
        )
    if summary["status"] != "ok":
        raise RunFailed(f"the solver failed ({summary['status']}) after {summary['solver_steps']} steps", summary)
    return summary


def sweep_command(args) -> dict:
    import jax

    from growjax import sweep as sw
    from growjax.cli import _sweep as cs
    from growjax.data import experiment as ex
    from growjax.plotting import sobol_figure, sweep_figure

    if args.resume:
        cs.restore(args)
    data, exp, base, origin = _setup(args, args.drive)
    dims = tuple(sw.parse_dimension(p, base) for p in args.range) if args.range else sw.paper_box()
    config = make_config(args, args.drive)
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    measured = (exp.time, exp["robot_length_m"]) if "robot_length_m" in exp else None
    leader = jax.process_index() == 0
    progress = not args.quiet and leader
    try:
        if args.resume:
            result = sw.resume(
                cs.store_path(args.out), base, inputs, measured, progress=progress, max_chunks=args.max_chunks
            )
        else:
            store = cs.prepare_new(args.out) if leader else cs.store_path(args.out)
            result = sw.lhs_sweep(
                args.n,
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
    if not leader:  # process 0 writes the files and reports
        return {"command": "sweep", "process_index": jax.process_index()}
    out = _out(args)
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
        "command": "sweep",
        "data": str(data),
        "drive": args.drive,
        "fidelity": config.fidelity,
        "t_end_s": args.t_end,
        "n": args.n,
        "seed": args.seed,
        "parameters": origin,
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
    if args.sobol:
        sob = sw.sobol_indices(
            dims,
            base,
            inputs,
            config,
            n_base=args.sobol_n,
            seed=args.seed,
            measured=measured,
            chunk_size=args.chunk_size,
            progress=not args.quiet,
        )
        summary["sobol"] = {
            "names": sob["names"],
            "n_runs": sob["n_runs"],
            "indices": sob["indices"],
            "wall_s": sob["sweep"].wall_s,
        }
        summary["sobol_figure"] = str(
            sobol_figure(sob, out / "sobol.png", title=f"Sobol indices ({sob['n_runs']} runs)")
        )
    if summary["n_failed"]:
        reasons = ", ".join(f"{n} {why}" for why, n in failed.items())
        raise RunFailed(
            f"{summary['n_failed']} of {args.n} sweep members failed ({reasons}); see {out / 'sweep.csv'}", summary
        )
    return summary


def fit_command(args) -> dict:
    import growjax as gj
    from growjax.calibration import fit as gf
    from growjax.data import experiment as ex
    from growjax.plotting import trajectory_figure

    paths = list(args.data or [])
    if len(paths) > 1 or (paths and Path(paths[0]).suffix.lower() == ".toml"):
        return _fit_set(args, paths)
    args.data = paths[0] if paths else None

    data, exp, base, origin = _setup(args, args.drive)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to fit")
    config = make_config(args, args.drive, adjoint="forward")
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    pressure = exp["pressure_Pa"] if "pressure_Pa" in exp else None  # noqa: SIM401 (Experiment is not a dict)
    started = _progress_note(args, f"fit: {', '.join(args.free or ['Y'])} from {args.starts} starts")
    result = gf.fit(
        exp.time,
        exp["robot_length_m"],
        inputs,
        free=args.free or ["Y"],
        base=base,
        config=config,
        pressure=pressure,
        n_starts=args.starts,
        seed=args.seed,
        window=scored_window(args, config),
        discrepancy=args.discrepancy,
        tolerances=tolerances_of(args),
        rig=args.rig,
        relinearise=args.relinearise,
        rig_tangents=args.rig_tangents,
    )
    _progress_note(args, f"fit: done in {time.perf_counter() - started:.1f} s")
    out = _out(args)
    fitted = gj.replace(base, **result.rig_estimate, **result.estimate)
    traj = gj.simulate(fitted, inputs, config)
    fig = trajectory_figure(
        traj,
        out / "fit.png",
        measured=(exp.time, exp["robot_length_m"]),
        title=f"fit of {', '.join(result.names)}: RMSE {1e3 * result.rmse_length_m:.2f} mm",
    )
    summary = {
        "command": "fit",
        "data": str(data),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "t_start_s": scored_window(args, config)[0],
        "fidelity": config.fidelity,
        "fixed_parameters": origin,
        **result.summary(),
        "figure": str(fig),
    }
    if result.status != "converged":
        raise RunFailed(
            f"the fit did not converge ({result.status}); try more --starts or fewer free parameters", summary
        )
    return summary


def posterior_command(args) -> dict:
    from growjax import posterior as gpost
    from growjax.data import experiment as ex

    paths = list(args.data or [])
    if args.hierarchical is not None:
        return _population(args, paths)
    if len(paths) > 1 or (paths and Path(paths[0]).suffix.lower() == ".toml"):
        raise ValueError(
            "a posterior over several experiments is the population's: give --hierarchical NAME "
            "(for one robot's experiments, `growjax fit` gives their joint intervals)"
        )
    args.data = paths[0] if paths else None
    data, exp, base, origin = _setup(args, args.drive, growth_law=args.law)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to calibrate against")
    config = make_config(args, args.drive, adjoint="forward")
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    priors = gpost.paper_priors() if args.law == "reference" else gpost.lockhart_priors()
    res = gpost.sample(
        exp.time,
        exp["robot_length_m"],
        inputs,
        base,
        config,
        priors=priors,
        chains=args.chains,
        warmup=args.warmup,
        samples=args.samples,
        seed=args.seed,
        progress=not args.quiet,
        emulate=args.emulate,
        window=scored_window(args, config),
        discrepancy=args.discrepancy,
        tolerances=tolerances_of(args),
    )
    out = _out(args)
    res.idata.to_netcdf(str(out / "posterior.nc"))
    summary = {
        "command": "posterior",
        "data": str(data),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fidelity": config.fidelity,
        "growth_law": args.law,
        "fixed_parameters": origin,
        **res.summary,
        "inference_data": str(out / "posterior.nc"),
    }
    rhat = summary.get("rhat_max")
    if args.chains > 1 and (rhat is None or not math.isfinite(rhat) or rhat > 1.1):
        raise RunFailed(f"the chains did not mix (R-hat max {rhat}); run more --warmup and --samples", summary)
    return summary


def discover_command(args) -> dict:
    from growjax import discover as gd
    from growjax.data import experiment as ex
    from growjax.plotting import discovery_figure

    paths = list(args.data or [])
    if len(paths) > 1 or (paths and Path(paths[0]).suffix.lower() == ".toml"):
        return _discover_set(args, paths)
    args.data = paths[0] if paths else None
    data, exp, base, origin = _setup(args, args.drive)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to explain")
    config = make_config(args, args.drive, adjoint="forward")
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    t0, t1 = scored_window(args, config)
    keep = (exp.time >= t0) & (exp.time <= t1)
    res = gd.discover(
        exp.time[keep],
        exp["robot_length_m"][keep],
        inputs,
        base=base,
        config=config,
        candidates=args.candidates or None,
        progress=not args.quiet,
        workers=args.workers,
        discrepancy=args.discrepancy,
        tolerances=tolerances_of(args),
    )
    out = _out(args)
    figure = discovery_figure(res, out / "discover.png", title=f"{data.name}: {res.effect}")
    return {
        "command": "discover",
        "data": str(data),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fixed_parameters": origin,
        **res.report(),
        "figure": str(figure),
        "text": gd.summary_text(res),
    }


def _discover_set(args, paths) -> dict:
    """``growjax discover A.csv B.csv …`` or ``growjax discover SET.toml``: each effect tested by the set's joint
    fits, its parameter one value per robot."""
    from growjax import discover as gd

    if len(paths) > 1 and any(Path(p).suffix.lower() == ".toml" for p in paths):
        raise ValueError("a manifest (.toml) describes the whole set: give it alone")
    config = make_config(args, args.drive, adjoint="forward")
    exps = _read_set(args, paths, config)
    started = _progress_note(
        args,
        f"discover: {len(args.candidates or gd.fx.CATALOGUE)} candidates over "
        f"{len(exps)} experiments, one joint fit each",
    )
    res = gd.discover_set(
        exps,
        config=config,
        candidates=args.candidates or None,
        seed=args.seed,
        discrepancy=args.discrepancy,
        tolerances=tolerances_of(args),
    )
    _progress_note(args, f"discover: done in {time.perf_counter() - started:.1f} s")
    return {
        "command": "discover",
        "data": [str(p) for p in paths],
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fixed_parameters": {"fixed": dict(parse_param(p) for p in args.param)},
        "experiments": [{"name": r.name, "robot": r.robot, "rig": r.rig, "window": r.window} for r in exps],
        **res.report(),
        "text": gd.set_summary_text(res),
    }


def control_command(args) -> dict:
    """Design on the fast model, evaluate on ``--fidelity``, write a figure."""
    from growjax import control as gc

    if args.rtol is not None:
        raise ValueError("growjax control does not take --rtol: designs use each configuration's default tolerance")
    data, exp, base, origin = _setup(args, args.drive)
    target = gc.target_from_experiment(exp, args.t_end)
    out = _out(args)
    started = _progress_note(args, f"control: {args.method} design on the fast model, evaluated on {args.fidelity}")
    summary = gc.design(
        target,
        args.drive,
        args.method,
        args.t_end,
        robust=args.robust,
        n_draws=args.draws,
        iterations=args.iterations,
        microsteps=args.microsteps,
        evaluate_on=args.fidelity,
        seed=args.seed,
        figure=out / "control.png",
        base=base,
        tolerances=tolerances_of(args),
    )
    _progress_note(args, f"control: done in {time.perf_counter() - started:.1f} s")
    summary = {"command": "control", "data": str(data), "fixed_parameters": origin, **summary}
    if summary.get("pressure_limit_crossed"):
        raise RunFailed(
            f"the design crossed the membrane pressure limit ({summary['pressure_limit_Pa'] / 1e3:.1f} kPa; "
            f"peak {summary['peak_pressure_Pa'] / 1e3:.1f} kPa)",
            summary,
        )
    rmse = summary.get("tracking_rmse_m")
    if rmse is None or not math.isfinite(rmse) or summary.get("status") not in ("ok", None):
        raise RunFailed(f"the evaluation run failed ({summary.get('status')})", summary)
    return summary


def design_command(args) -> dict:
    """What is known (a fit of DATA, or --fit-from), then the design; writes design.csv, design.png, summary.json."""
    from growjax import design as gd
    from growjax.calibration import fit as gf
    from growjax.data import experiment as ex
    from growjax.model import params as gp

    stepper = args.next_drive == "inverse"
    if stepper and args.discriminate is not None:
        raise ValueError("--discriminate designs the forward drive's demand: drop --next-drive inverse")
    if stepper and (args.knot_spacing is not None or args.p_max is not None):
        raise ValueError(
            "--knot-spacing and --p-max shape the forward drive's demand; the stepper's schedule has "
            "neither (its steps are the controller's, at most one per period)"
        )
    if args.fidelity != "fast":
        raise ValueError("growjax design runs the fast configuration (its sensitivities are differentiated again)")
    if args.discriminate is not None:
        from growjax.design import discrimination as ddis

        if args.design_for:
            raise ValueError("--for designs for precision, --discriminate to tell two effects apart: give one of them")
        from growjax.data import synthetic as syn

        ddis.rivals(args.discriminate)
        if args.size is not None and len(args.size) != 2:
            raise ValueError(f"--size takes one size per effect of --discriminate (two), got {len(args.size)}")
        for effect, size in zip(args.discriminate, args.size or ()):
            syn.make_effect(effect, size)  # ValueError outside its physical range
        if args.sensors != "length":
            raise ValueError("--discriminate scores the length alone: drop --sensors")
    elif args.size is not None:
        raise ValueError("--size gives the effects' sizes of --discriminate")
    data, exp, base, origin = _setup(args, args.drive, growth_law=args.law)
    names = tuple(dict.fromkeys(gp.resolve_name(base, n) for n in (args.design_for or ["Y"])))
    base_next = base if args.next_drive == args.drive else _setup(args, args.next_drive, growth_law=args.law)[2]
    lim = gd.limits(base_next, max_speed=args.max_pump_speed)
    if stepper:
        space = gd.stepper_space(base_next, args.duration, exp)
    else:
        p_max = lim.pressure if args.p_max is None else args.p_max
        if p_max > lim.pressure + 1e-9:
            raise ValueError(
                f"--p-max {p_max / 1e3:.1f} kPa is above the sensed-pressure ceiling "
                f"{lim.pressure / 1e3:.1f} kPa (the membrane limit {lim.membrane / 1e3:.1f} kPa × the margin)"
            )
        space = gd.DesignSpace(
            args.duration,
            p_max,
            gd.catheter_of(exp, args.duration),
            0.5 if args.knot_spacing is None else args.knot_spacing,
        )
    tolerances = tolerances_of(args)
    if args.fit_from:
        known = gd.from_summary(args.fit_from, base, names, tolerances)
    else:
        if "robot_length_m" not in exp:
            raise ValueError(f"{data} has no robot_length_m column to fit: give what is known with --fit-from")
        config = make_config(args, args.drive, adjoint="forward")
        inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
        pressure = exp["pressure_Pa"] if "pressure_Pa" in exp else None  # noqa: SIM401 (Experiment is not a dict)
        started = _progress_note(args, f"design: what is known, a fit of {', '.join(names)} to {data.name}")
        fitted = gf.fit(
            exp.time,
            exp["robot_length_m"],
            inputs,
            free=names,
            base=base,
            config=config,
            pressure=pressure,
            seed=args.seed,
            window=scored_window(args, config),
            discrepancy=args.discrepancy,
            tolerances=tolerances,
        )
        _progress_note(args, f"design: fitted in {time.perf_counter() - started:.1f} s")
        known = gd.from_fit(fitted, base, tolerances)
    if base_next is not base:
        known = known.on(base_next)  # θ as fitted, on the next experiment's drive
    if args.discriminate is not None:
        started = _progress_note(args, f"design: to tell {' from '.join(args.discriminate)}, {args.duration:g} s")
        result = gd.discriminate(
            known,
            space,
            args.discriminate,
            args.size,
            random=args.random,
            starts=args.starts,
            iterations=args.iterations,
            n_draws=args.draws,
            seed=args.seed,
            limits=lim,
            progress=not args.quiet,
        )
    else:
        what = "step schedule" if stepper else "demand"
        started = _progress_note(
            args,
            f"design: {args.criterion}-optimal {what} for {', '.join(names)}, "
            f"{args.duration:g} s, sensors {args.sensors}",
        )
        result = gd.design(
            known,
            space,
            criterion=args.criterion,
            sensors=tuple(args.sensors.split(",")),
            random=args.random,
            starts=args.starts,
            iterations=args.iterations,
            n_draws=args.draws,
            seed=args.seed,
            points=args.points,
            pressure_noise=args.pressure_noise,
            limits=lim,
            nonlinear_draws=args.nonlinear_draws,
            progress=not args.quiet,
        )
    _progress_note(args, f"design: done in {time.perf_counter() - started:.1f} s")
    out = _out(args)
    csv = space.write_csv(out / "design.csv", result.x)
    figure = gd.design_figure(result, out / "design.png")
    summary = {
        "command": "design",
        "data": str(data),
        "data_drive": args.drive,
        "fixed_parameters": origin,
        "growth_law": args.law,
        **result.summary(),
        "design_csv": str(csv),
        "figure": str(figure),
        "summary_json": str(out / "summary.json"),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    return summary


def params_command(args) -> dict:
    import growjax as gj
    from growjax.model import params as gp

    base = gj.reference(args.drive)
    symbols = {q: s for s, q in gp.ALIASES.items() if s not in ("phi",)}
    ranges = gp.physical_ranges(base)
    rows = []
    for q in gp.parameter_names(base):
        block, field = q.split(".")
        value = gp.get(base, q)
        if value is None or np.ndim(value) != 0:
            continue
        cls = type(getattr(base, block))
        about = _attribute_text(cls.__doc__ or "", field)
        lo, hi, unit = ranges.get(q, (None, None, ""))
        unit = unit or _unit_of(about)
        rows.append(
            {
                "name": q,
                "symbol": symbols.get(q, ""),
                "value": float(value),
                "unit": unit,
                "range": None if lo is None else [lo, hi],
                "description": about,
            }
        )
    return {"command": "params", "drive": args.drive, "parameters": rows}


def _attribute_text(doc: str, field: str) -> str:
    """The description of ``field`` in a Google-style ``Attributes:`` section (one line), or ''."""
    import re

    flat = " ".join(doc.split("Attributes:", 1)[-1].split())
    m = re.search(rf"(?:^|[\s.:]){re.escape(field)}: (.*?)(?=\s+[a-z_]+: |$)", flat)
    return m.group(1).strip() if m else ""


def _unit_of(description: str) -> str:
    """The SI unit a docstring states at the end of a parameter's description ("..., kg/m³.", "... (–)."), or ''."""
    import re

    text = re.sub(r"\s*\((?![^()]*/)[^()]*\)\.?$", "", description.strip()).rstrip(". ")  # drop a closing remark
    if "(–)" in description and not re.search(r",\s*\S+$", text):
        return "-"
    last = text.rsplit(", ", 1)[-1] if ", " in text else text
    last = last.split(":")[0].split(";")[0].strip()
    if (
        last
        and " " not in last
        and len(last) <= 16
        and (not last.isalpha() or last in ("m", "s", "N", "Pa", "kg", "V", "A", "H", "rad", "Hz", "Ω"))
    ):
        return last
    return "-" if "(–)" in description else ""


def effects_command(args) -> dict:
    from growjax.discover import SEPARATING
    from growjax.model.effects import CATALOGUE

    rows = []
    for name, cls in CATALOGUE.items():
        ((field, (lo, hi)),) = cls.ranges.items()
        rows.append(
            {
                "name": name,
                "parameter": f"{name}.{field}",
                "unit": cls.units.get(field, ""),
                "range": [lo, hi],
                "description": cls.description,
                "separated_by": SEPARATING.get(name, ""),
            }
        )
    return {"command": "effects", "effects": rows}


COMMANDS = {
    "simulate": simulate_command,
    "sweep": sweep_command,
    "fit": fit_command,
    "posterior": posterior_command,
    "discover": discover_command,
    "control": control_command,
    "params": params_command,
    "effects": effects_command,
    "design": design_command,
    "track": lambda args: _track_run(args),
}


def _track_run(args) -> dict:
    from growjax.cli import track as track_command

    return track_command.run(args)


def _write_json(summary: dict, where: str | None):
    if not where:
        return
    text = json.dumps({k: v for k, v in summary.items() if k != "text"}, indent=2, default=str)
    if where == "-":
        print(text)
    else:
        Path(where).parent.mkdir(parents=True, exist_ok=True)
        Path(where).write_text(text + "\n")


def main(argv=None) -> int:
    import matplotlib

    matplotlib.use("Agg")  # the commands write figures to files
    args = build_parser().parse_args(argv)
    to_stdout = getattr(args, "json", None) == "-"
    human = sys.stderr if to_stdout else sys.stdout
    if args.command in ("params", "effects"):
        summary = COMMANDS[args.command](args)
        _write_json(summary, args.json)
        if not to_stdout:
            print("\n".join(summary_lines(summary)), file=human)
        return OK
    _enable_compile_cache()
    from growjax.simulation import xla_flags

    if args.command in ("simulate", "fit") and args.fidelity == "fast":  # compile-bound: XLA's quicker emitters
        xla_flags.apply_quick_compile()
    if args.command in ("fit", "discover"):
        _use_all_cpu_cores()  # a set's runs spread over the cores (growjax.calibration.joint)
    elif args.command == "sweep":
        _use_all_cpu_cores()
    elif args.command == "posterior":
        _use_all_cpu_cores(at_least=args.chains)  # chains in parallel, one per device
        if (
            not args.emulate and args.hierarchical is None
        ):  # thousands of gradients through the solver: its loop compiled whole
            xla_flags.apply()
    from growjax.cli._sweep import Stopped, start_distributed
    from growjax.data.datasets import DatasetError
    from growjax.data.experiment import ExperimentError

    status, failure = OK, None
    try:
        if args.command == "sweep":
            start_distributed(args)
        summary = COMMANDS[args.command](args)
    except np.linalg.LinAlgError:  # a ValueError, but a failure of the computation, not of the input
        raise
    except (ExperimentError, ValueError, FileNotFoundError, DatasetError) as err:
        print(f"growjax {args.command}: error: {err}", file=sys.stderr)
        return BAD_INPUT
    except RunFailed as failed:
        summary, status, failure = failed.summary, RUN_FAILED, str(failed)
        summary["failure"] = failure
    except Stopped as stop:
        print(f"growjax {args.command}: {stop}", file=sys.stderr)
        return stop.status
    if summary.get("process_index", 0):  # a worker of a distributed sweep: process 0 reports
        return status
    _write_json(summary, args.json)
    print("\n".join(summary_lines(summary)), file=human)
    if failure:
        print(f"growjax {args.command}: failed: {failure}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
