"""Command line: ``growjax COMMAND [DATA] [options]`` (``growjax --help``, ``growjax COMMAND --help``).

Every workflow command takes the same shared options (``--drive``, ``--param``, ``--fidelity``, ``--rtol``,
``--seed``, ``--t-end``, ``--out``, ``--json``), prints a short summary in mm and kPa, and exits with status 0 when
its runs succeeded, 1 when a run failed (the reason on stderr) and 2 for a bad option or file.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from growjax._data import default_data_path

OK, RUN_FAILED, BAD_INPUT = 0, 1, 2
DRIVES = ("forward", "inverse")
FIDELITIES = ("fast", "reference")


class RunFailed(Exception):
    """A run finished but failed (solver failure, failed sweep member, fit not converged, limit crossed)."""

    def __init__(self, reason: str, summary: dict):
        super().__init__(reason)
        self.summary = summary


class _Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's default shown, except where its help already says it."""

    def _get_help_string(self, action):
        if "(default:" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block) naming the problem and the valid values."""

    def error(self, message):
        self.exit(BAD_INPUT, f"{self.prog}: error: {message}\n")


def _enable_compile_cache():
    import jax

    cache = os.environ.get("GROWJAX_CACHE_DIR", str(Path.home() / ".cache" / "growjax" / "jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


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


def _effect_name(text: str) -> str:
    from growjax.effects import CATALOGUE

    if text not in CATALOGUE:
        raise argparse.ArgumentTypeError(f"unknown effect {text!r}; choose from {', '.join(CATALOGUE)}")
    return text


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


def _setup(args, drive: str, growth_law: str = "reference"):
    """(data path, experiment, parameters, what they came from) for a workflow command."""
    import growjax as gj
    from growjax import experiment as ex

    data = Path(args.data) if args.data else default_data_path()
    exp = ex.read(data).window(args.t_end + 1e-9)
    params = gj.reference(drive, growth_law=growth_law)
    recorded = recorded_parameters(data)
    fixed = dict(parse_param(p) for p in args.param)
    values = {**recorded, **fixed}
    if values:
        params = gj.replace(params, **values)
    gj.validate(params)
    origin = {"recorded_beside_data": {k: v for k, v in recorded.items() if k not in fixed}, "fixed": fixed}
    return data, exp, params, origin


def make_config(args, drive: str = "forward", **extra):
    """The :class:`growjax.Config` named by the shared options (--fidelity, --rtol, --t-end)."""
    import growjax as gj

    return gj.Config(fidelity=args.fidelity, drive=drive, t1=args.t_end, rtol=args.rtol, atol=args.rtol, **extra)


def _out(args) -> Path:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    return out


# -- commands ---------------------------------------------------------------------------------------------------


def simulate_command(args) -> dict:
    import jax

    import growjax as gj
    from growjax import experiment as ex
    from growjax.metrics import length_rmse
    from growjax.plotting import trajectory_figure

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
    summary["figure"] = str(trajectory_figure(
        traj, out / "trajectory.png", measured=measured,
        desired=(np.asarray(traj.time), series["desired_length_m"]) if args.drive == "inverse" else None,
        title=title, pressure_limit=summary["pressure_limit_Pa"]))
    if summary["status"] == "pressure_limit":
        raise RunFailed(f"the sensed pressure crossed the membrane limit ({summary['pressure_limit_Pa'] / 1e3:.1f} kPa) "
                        f"at t = {summary['limit_time_s']:.3f} s; the run stopped there", summary)
    if summary["status"] != "ok":
        raise RunFailed(f"the solver failed ({summary['status']}) after {summary['solver_steps']} steps", summary)
    return summary


def sweep_command(args) -> dict:
    import jax

    from growjax import experiment as ex
    from growjax import sweep as sw
    from growjax.plotting import sobol_figure, sweep_figure

    data, exp, base, origin = _setup(args, args.drive)
    dims = tuple(sw.parse_dimension(p, base) for p in args.range) if args.range else sw.paper_box()
    config = make_config(args, args.drive)
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    measured = (exp.time, exp["robot_length_m"]) if "robot_length_m" in exp else None
    result = sw.lhs_sweep(args.n, base, inputs, config, dims, seed=args.seed, measured=measured,
                          chunk_size=args.chunk_size, progress=True)
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
        "figure": str(fig),
    }
    if args.sobol:
        sob = sw.sobol_indices(dims, base, inputs, config, n_base=args.sobol_n, seed=args.seed, measured=measured,
                               chunk_size=args.chunk_size, progress=True)
        summary["sobol"] = {"names": sob["names"], "n_runs": sob["n_runs"], "indices": sob["indices"],
                            "wall_s": sob["sweep"].wall_s}
        summary["sobol_figure"] = str(sobol_figure(sob, out / "sobol.png", title=f"Sobol indices ({sob['n_runs']} runs)"))
    if summary["n_failed"]:
        reasons = ", ".join(f"{n} {why}" for why, n in failed.items())
        raise RunFailed(f"{summary['n_failed']} of {args.n} sweep members failed ({reasons}); see {out / 'sweep.csv'}",
                        summary)
    return summary


def fit_command(args) -> dict:
    import growjax as gj
    from growjax import experiment as ex
    from growjax import fit as gf
    from growjax.plotting import trajectory_figure

    data, exp, base, origin = _setup(args, args.drive)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to fit")
    config = make_config(args, args.drive, adjoint="forward")
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    pressure = exp["pressure_Pa"] if "pressure_Pa" in exp else None  # noqa: SIM401 (Experiment is not a dict)
    result = gf.fit(exp.time, exp["robot_length_m"], inputs, free=args.free or ["Y"], base=base, config=config,
                    pressure=pressure, n_starts=args.starts, seed=args.seed, window=_window(args, config),
                    discrepancy=args.discrepancy, tolerances=_tolerances(args))
    out = _out(args)
    fitted = gj.replace(base, **result.estimate)
    traj = gj.simulate(fitted, inputs, config)
    fig = trajectory_figure(traj, out / "fit.png", measured=(exp.time, exp["robot_length_m"]),
                            title=f"fit of {', '.join(result.names)}: RMSE {1e3 * result.rmse_length_m:.2f} mm")
    summary = {"command": "fit", "data": str(data), "drive": args.drive, "t_end_s": args.t_end,
               "t_start_s": _window(args, config)[0],
               "fidelity": config.fidelity, "fixed_parameters": origin, **result.summary(), "figure": str(fig)}
    if result.status != "converged":
        raise RunFailed(f"the fit did not converge ({result.status}); try more --starts or fewer free parameters",
                        summary)
    return summary


def posterior_command(args) -> dict:
    from growjax import experiment as ex
    from growjax import posterior as gpost

    data, exp, base, origin = _setup(args, args.drive, growth_law=args.law)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to calibrate against")
    config = make_config(args, args.drive, adjoint="forward")
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    priors = gpost.paper_priors() if args.law == "reference" else gpost.lockhart_priors()
    res = gpost.sample(exp.time, exp["robot_length_m"], inputs, base, config, priors=priors, chains=args.chains,
                       warmup=args.warmup, samples=args.samples, seed=args.seed, progress=True,
                       emulate=args.emulate, window=_window(args, config), discrepancy=args.discrepancy,
                       tolerances=_tolerances(args))
    out = _out(args)
    res.idata.to_netcdf(str(out / "posterior.nc"))
    summary = {"command": "posterior", "data": str(data), "drive": args.drive, "t_end_s": args.t_end,
               "fidelity": config.fidelity, "growth_law": args.law, "fixed_parameters": origin, **res.summary,
               "inference_data": str(out / "posterior.nc")}
    rhat = summary.get("rhat_max")
    if args.chains > 1 and (rhat is None or not math.isfinite(rhat) or rhat > 1.1):
        raise RunFailed(f"the chains did not mix (R-hat max {rhat}); run more --warmup and --samples", summary)
    return summary


def discover_command(args) -> dict:
    from growjax import discover as gd
    from growjax import experiment as ex
    from growjax.plotting import discovery_figure

    data, exp, base, origin = _setup(args, args.drive)
    if "robot_length_m" not in exp:
        raise ValueError(f"{data} has no robot_length_m column to explain")
    config = make_config(args, args.drive, adjoint="forward")
    inputs = ex.to_inputs(exp, args.drive, base, config.t0, config.t1)
    t0, t1 = _window(args, config)
    keep = (exp.time >= t0) & (exp.time <= t1)
    res = gd.discover(exp.time[keep], exp["robot_length_m"][keep], inputs, base=base, config=config,
                      candidates=args.candidates or None, progress=True, workers=args.workers,
                      discrepancy=args.discrepancy)
    out = _out(args)
    figure = discovery_figure(res, out / "discover.png", title=f"{data.name}: {res.effect}")
    return {"command": "discover", "data": str(data), "drive": args.drive, "t_end_s": args.t_end,
            "fixed_parameters": origin, **res.report(), "figure": str(figure), "text": gd.summary_text(res)}


def control_command(args) -> dict:
    """Design on the fast model, evaluate on ``--fidelity``, write a figure."""
    import importlib

    from growjax import experiment as ex

    design_module = importlib.import_module("growjax.control.design")  # the module (the package re-exports design())
    targets_module = importlib.import_module("growjax.control.targets")

    if args.rtol is not None:
        raise ValueError("growjax control does not take --rtol: designs use each configuration's default tolerance")
    data, _, _, origin = _setup(args, args.drive)
    target = targets_module.target_from_experiment(ex.read(data), args.t_end)
    fixed = {**origin["recorded_beside_data"], **origin["fixed"]}
    out = _out(args)
    with contextlib.ExitStack() as stack:
        if fixed:  # the designs start from the published parameters: give them the fixed ones instead
            from unittest import mock

            import growjax as gj

            def plant_params(drive, target=None, base=None):
                return targets_module.plant_params(drive, target, base=gj.replace(gj.reference(drive), **fixed))

            stack.enter_context(mock.patch.object(design_module, "plant_params", plant_params))
        summary = design_module.design(target, args.drive, args.method, args.t_end, robust=args.robust,
                                       n_draws=args.draws, iterations=args.iterations, microsteps=args.microsteps,
                                       evaluate_on=args.fidelity, seed=args.seed, figure=out / "control.png")
    summary = {"command": "control", "data": str(data), "fixed_parameters": origin, **summary}
    if summary.get("pressure_limit_crossed"):
        raise RunFailed(f"the design crossed the membrane pressure limit ({summary['pressure_limit_Pa'] / 1e3:.1f} kPa; "
                        f"peak {summary['peak_pressure_Pa'] / 1e3:.1f} kPa)", summary)
    rmse = summary.get("tracking_rmse_m")
    if rmse is None or not math.isfinite(rmse) or summary.get("status") not in ("ok", None):
        raise RunFailed(f"the evaluation run failed ({summary.get('status')})", summary)
    return summary


def params_command(args) -> dict:
    import growjax as gj
    from growjax import params as gp

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
        rows.append({"name": q, "symbol": symbols.get(q, ""), "value": float(value), "unit": unit,
                     "range": None if lo is None else [lo, hi], "description": about})
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
    if last and " " not in last and len(last) <= 16 and (not last.isalpha() or last in ("m", "s", "N", "Pa", "kg",
                                                                                         "V", "A", "H", "rad", "Hz", "Ω")):
        return last
    return "-" if "(–)" in description else ""


def effects_command(args) -> dict:
    from growjax.discover import SEPARATING
    from growjax.effects import CATALOGUE

    rows = []
    for name, cls in CATALOGUE.items():
        (field, (lo, hi)), = cls.ranges.items()
        rows.append({"name": name, "parameter": f"{name}.{field}", "unit": cls.units.get(field, ""),
                     "range": [lo, hi], "description": cls.description,
                     "separated_by": SEPARATING.get(name, "")})
    return {"command": "effects", "effects": rows}


# -- terminal summaries -----------------------------------------------------------------------------------------


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


def summary_lines(s: dict) -> list[str]:
    """A few lines for the terminal, in mm and kPa."""
    cmd = s.get("command")
    name = Path(s["data"]).name if s.get("data") else ""
    if cmd == "simulate":
        lines = [f"simulate: {name}, {s['drive']} drive, {s['fidelity']} configuration, 0–{s['t_end_s']:g} s",
                 *_origin_lines(s["parameters"]),
                 (f"  status {s['status']}; final length {_mm(s['final_length_m'])}; peak pressure "
                 f"{_kpa(s['peak_pressure_Pa'])} (membrane limit {_kpa(s['pressure_limit_Pa'])})")]
        if "rmse_length_m" in s:
            lines.append(f"  length RMSE against the measured length: {_mm(s['rmse_length_m'])}")
        lines.append(f"  {s['solver_steps']} solver steps, {1e3 * s['wall_s']:.0f} ms after compiling "
                     f"({s['first_call_s']:.1f} s first call)")
        lines.append(f"  wrote {s['trajectory_csv']}, {s['figure']}")
        return lines
    if cmd == "sweep":
        ranges = ", ".join(f"{r['name']} {r['low']:g}–{r['high']:g}" + (" (log)" if r["log"] else "") for r in s["ranges"])
        lines = [f"sweep: {name}, {s['n']} sets (seed {s['seed']}) over {ranges}", *_origin_lines(s["parameters"]),
                 (f"  {s['n_failed']} failed; sweep {s['wall_s']:.2f} s after {s['compile_s']:.1f} s compiling, "
                 f"{s['n_devices']} {s['device']} devices")]
        if s.get("best"):
            best = ", ".join(f"{k} = {_value(k, v)}" for k, v in s["best"]["parameters"].items())
            lines.append(f"  best: {best}; length RMSE {_mm(s['best']['rmse_length_m'])}")
        for output, table in s.get("sobol", {}).get("indices", {}).items():
            if "S1" in table:
                shown = ", ".join(f"{n.split('.')[-1]} {a:.2f}/{b:.2f}" for n, a, b in
                                  zip(s["sobol"]["names"], table["S1"], table["ST"]))
                lines.append(f"  Sobol S1/ST of {output}: {shown}")
        lines.append(f"  wrote {s['table_csv']}, {s['figure']}")
        return lines
    if cmd == "fit":
        lines = [f"fit: {name}, {s['drive']} drive, {s.get('t_start_s', 0.0):g}–{s['t_end_s']:g} s scored: {s['status']}",
                 *_origin_lines(s["fixed_parameters"])]
        for p, v in s["parameters"].items():
            interval = v["interval_90"]
            shown = "undetermined" if interval is None else f"90 % {_value(p, interval[0])} – {_value(p, interval[1])}"
            lines.append(f"  {p} = {_value(p, v['estimate'])} ({shown})")
            if v.get("budget_sd"):
                parts = sorted(v["budget_sd"].items(), key=lambda kv: -kv[1])
                lines.append("    sd from " + ", ".join(f"{k} {_value(p, x)}" for k, x in parts if x > 0))
        d = s.get("discrepancy") or {}
        if d.get("kind") == "matern32":
            lines.append(f"  discrepancy {_mm(d['amplitude_m'])} over {d['time_scale_s']:.2g} s, noise "
                         f"{_mm(d['noise_m'])}; {s['samples_used']} samples scored")
        elif d:
            lines.append(f"  independent noise {_mm(d['noise_m'])}")
        lines.append(f"  length RMSE {_mm(s['rmse_length_m'])}; {s['wall_s']:.1f} s")
        lines.append(f"  wrote {s['figure']}")
        return lines
    if cmd == "posterior":
        lines = [(f"posterior: {name}, {s['growth_law']} growth law, {s['chains']} chains × "
                 f"({s['warmup']} + {s['samples']})"), *_origin_lines(s["fixed_parameters"])]
        for p, v in s["parameters"].items():
            lo, hi = v["interval_90"]
            if p == "sigma":
                lines.append(f"  σ = {_mm(v['mean'])} (90 % {_mm(lo)} – {_mm(hi)})")
            else:
                lines.append(f"  {p} = {_value(p, v['mean'])} (90 % {_value(p, lo)} – {_value(p, hi)})")
        lines.append(f"  R-hat max {s['rhat_max']:.3f}, bulk ESS min {s['ess_bulk_min']:.0f}, divergences "
                     f"{s['divergences']}, measured points in the 90 % band {s['coverage_90']:.2f}; {s['wall_s']:.0f} s")
        lines.append(f"  wrote {s['inference_data']}")
        return lines
    if cmd == "discover":
        return [f"discover: {name}", *_origin_lines(s["fixed_parameters"]),
                *("  " + line for line in s["text"].splitlines()), f"  wrote {s['figure']}"]
    if cmd == "control":
        lines = [(f"control: {name}, {s['drive']} drive, {s['method']}, evaluated on the {s['evaluated_on']} "
                 f"configuration"), *_origin_lines(s["fixed_parameters"]),
                 (f"  tracking RMSE {_mm(s.get('tracking_rmse_m'))}; peak pressure {_kpa(s.get('peak_pressure_Pa'))} "
                 f"(limit {_kpa(s.get('pressure_limit_Pa'))}, demand ceiling {_kpa(s.get('max_demand_Pa'))})")]
        if s.get("gains"):
            lines.append("  gains: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                                 for k, v in s["gains"].items()))
        if s.get("figure"):
            lines.append(f"  wrote {s['figure']}")
        return lines
    if cmd == "params":
        lines = [f"{'name':34s} {'symbol':7s} {'value':>12s} {'unit':16s} {'physical range':24s} description"]
        for r in s["parameters"]:
            rng = "" if r["range"] is None else f"{r['range'][0]:g} – {r['range'][1]:g}"
            lines.append(f"{r['name']:34s} {r['symbol']:7s} {r['value']:12.5g} {r['unit']:16s} {rng:24s} "
                         f"{r['description'][:70]}")
        return lines
    if cmd == "effects":
        lines = []
        for r in s["effects"]:
            lines.append(f"{r['name']}: {r['description']}")
            lines.append(f"    parameter {r['parameter']} in [{r['range'][0]:g}, {r['range'][1]:g}] {r['unit']}")
            lines.append(f"    separated by: {r['separated_by']}")
        return lines
    return [json.dumps(s, default=str)]


# -- the parser -------------------------------------------------------------------------------------------------


def _shared(p: argparse.ArgumentParser, command: str, fidelity_default: str = "fast", fidelity_help: str = ""):
    p.add_argument("data", nargs="?", default=None,
                   help="experiment CSV, or a folder with kings_ts.mat and lin_c_ts.mat (default: the synthetic "
                        "experiment shipped with growjax)")
    p.add_argument("--drive", choices=DRIVES, default="forward",
                   help="forward: PID on the pressure with ideal torque sources; inverse: stepper motor and its step "
                        "controller")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="fix a parameter, SI units (repeat; names as in `growjax params`); overrides values recorded "
                        "beside the data")
    p.add_argument("--fidelity", choices=FIDELITIES, default=fidelity_default,
                   help=fidelity_help or "configuration that solves the model: fast, or the reference network (slow)")
    p.add_argument("--rtol", type=float, default=None,
                   help="solver tolerance on the scaled states (None: 1e-4 fast, 1e-6 reference)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    p.add_argument("--t-end", type=float, default=10.0, metavar="S", help="end of the simulated window, s")
    p.add_argument("--out", default=str(Path("out") / command), metavar="DIR", help="folder for the files the command writes")
    p.add_argument("--json", metavar="FILE", default=None, help="write the full summary as JSON to FILE ('-': stdout)")


def _likelihood(p: argparse.ArgumentParser, tolerances: bool = True):
    """The options of the likelihood that fit, posterior and discover share."""
    p.add_argument("--t-start", type=float, default=None, metavar="S",
                   help="score only the data from this time on, s (the model still runs from the start)")
    p.add_argument("--discrepancy", choices=["matern32", "none"], default="matern32",
                   help="matern32: the model plus a smooth Matérn-3/2 discrepancy plus sensor noise; none: "
                        "independent noise around an exact model")
    if tolerances:
        p.add_argument("--tolerance", action="append", default=[], metavar="NAME=REL",
                       help="relative standard uncertainty of a fixed parameter, e.g. Kp=0.1 (repeat; overrides "
                            "the default budget of `growjax params`; 'none' drops the budget)")


def _tolerances(args):
    """The ``tolerances`` argument of fit and posterior from ``--tolerance`` (None: the default budget)."""
    from growjax import tolerance as tl

    if not args.tolerance:
        return None
    if [t.strip().lower() for t in args.tolerance] == ["none"]:
        return {}
    from growjax import params as gp

    base = gp.reference(args.drive)
    return {**tl.default_budget(base), **dict(tl.parse(t) for t in args.tolerance)}


def _window(args, config):
    t0 = config.t0 if args.t_start is None else args.t_start
    if not t0 < config.t1:
        raise ValueError(f"--t-start {t0} s must lie before --t-end {config.t1} s")
    return (t0, config.t1)


def build_parser():
    from growjax import __version__

    fmt = _Formatter
    parser = _Parser(prog="growjax", formatter_class=fmt,
                     description="MAMMOBOT soft growing robot: simulate, sweep, fit, sample, discover, control")
    parser.add_argument("--version", action="version", version=f"growjax {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    sim = sub.add_parser("simulate", formatter_class=fmt, help="simulate an experiment against its measured length")
    _shared(sim, "simulate")

    swp = sub.add_parser("sweep", formatter_class=fmt, help="Latin-hypercube sweep scored against the measured length")
    _shared(swp, "sweep")
    swp.add_argument("--n", type=int, default=500, help="number of parameter sets")
    swp.add_argument("--range", action="append", default=[], metavar="NAME=LOW:HIGH[:log]",
                     help="swept parameter and its range, SI units (repeat); none: the paper's n, Y, ext box")
    swp.add_argument("--sobol", action="store_true", help="also compute Sobol indices of RMSE and final length")
    swp.add_argument("--sobol-n", type=int, default=256, help="Saltelli base points (a power of 2; runs = N·(d+2))")
    swp.add_argument("--chunk-size", type=int, default=None, help="sets per compiled call (None: sized to memory)")

    fit = sub.add_parser("fit", formatter_class=fmt, help="least-squares fit to the measured length (and pressure)")
    _shared(fit, "fit")
    fit.add_argument("--free", action="append", default=[], metavar="NAME",
                     help="parameter to fit (repeat; none: Y)")
    fit.add_argument("--starts", type=int, default=3, help="starts, from the best sets of a Latin hypercube")
    _likelihood(fit)

    post = sub.add_parser("posterior", formatter_class=fmt,
                          help="NUTS posterior of Y, ext, n (or Y, phi_L, n_L) and the noise")
    _shared(post, "posterior")
    post.add_argument("--law", choices=["reference", "lockhart"], default="reference",
                      help="growth law: the published velocity term, or Lockhart's")
    post.add_argument("--emulate", action="store_true",
                      help="sample through a validated emulator of the model (fast; worth it where the data leave "
                           "directions flat, as ext and n of the published law)")
    post.add_argument("--chains", type=int, default=4, help="NUTS chains")
    post.add_argument("--warmup", type=int, default=500, help="warm-up draws per chain")
    post.add_argument("--samples", type=int, default=500, help="kept draws per chain")
    _likelihood(post)

    dis = sub.add_parser("discover", formatter_class=fmt,
                         help="which catalogue effect the data need beyond the model (`growjax effects`)")
    _shared(dis, "discover")
    dis.add_argument("--candidates", nargs="+", metavar="EFFECT", type=_effect_name, default=None,
                     help="catalogue effects to test (None: all of `growjax effects`)")
    dis.add_argument("--workers", type=int, default=None, help="fits run at a time (None: one per CPU core)")
    _likelihood(dis, tolerances=False)

    ctl = sub.add_parser("control", formatter_class=fmt,
                         help="length control design: open-loop profile, feedback, MPC")
    _shared(ctl, "control", fidelity_default="reference",
            fidelity_help="configuration the design is evaluated on (designs use the fast one)")
    ctl.add_argument("--method", choices=["open-loop", "feedback", "mpc"], default="feedback",
                     help="open-loop demand profile (or step schedule), tuned feedback, or MPC (forward drive)")
    ctl.add_argument("--robust", metavar="POSTERIOR.nc", default=None,
                     help="tune on the cost averaged over draws of this posterior")
    ctl.add_argument("--draws", type=int, default=8, help="posterior draws to tune on (with --robust)")
    ctl.add_argument("--iterations", type=int, default=10, help="optimiser and tuning iterations")
    ctl.add_argument("--microsteps", type=int, default=1, help="stepper driver microsteps (1: the full-step driver)")

    par = sub.add_parser("params", formatter_class=fmt,
                         help="list the parameters: names, symbols, defaults, units, physical ranges")
    par.add_argument("--drive", choices=DRIVES, default="forward", help="which drive's published parameter set")
    par.add_argument("--json", metavar="FILE", default=None, help="write the table as JSON to FILE ('-': stdout)")
    eff = sub.add_parser("effects", formatter_class=fmt,
                         help="list the effect catalogue: parameter, range, what separates each")
    eff.add_argument("--json", metavar="FILE", default=None, help="write the catalogue as JSON to FILE ('-': stdout)")
    return parser


COMMANDS = {"simulate": simulate_command, "sweep": sweep_command, "fit": fit_command,
            "posterior": posterior_command, "discover": discover_command, "control": control_command,
            "params": params_command, "effects": effects_command}


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
    from growjax import xla_flags

    if args.command in ("simulate", "fit") and args.fidelity == "fast":  # compile-bound: XLA's quicker emitters
        xla_flags.apply_quick_compile()
    elif args.command == "sweep":
        _use_all_cpu_cores()
    elif args.command == "posterior":
        _use_all_cpu_cores(at_least=args.chains)  # chains in parallel, one per device
        if not args.emulate:  # thousands of gradients through the solver: its loop compiled whole
            xla_flags.apply()
    from growjax.experiment import ExperimentError

    status, failure = OK, None
    try:
        summary = COMMANDS[args.command](args)
    except (ExperimentError, ValueError, FileNotFoundError) as err:
        print(f"growjax {args.command}: error: {err}", file=sys.stderr)
        return BAD_INPUT
    except RunFailed as failed:
        summary, status, failure = failed.summary, RUN_FAILED, str(failed)
        summary["failure"] = failure
    _write_json(summary, args.json)
    print("\n".join(summary_lines(summary)), file=human)
    if failure:
        print(f"growjax {args.command}: failed: {failure}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
