"""``growjax track DATA --sensors pressure,syringe``: the robot's length, pressure and estimated parameters over
time with 90 % bands, from the rig's own sensors (`growjax.track`).

Writes ``track.csv`` (``time_s``, each quantity with its band: ``robot_length_m``, ``robot_length_lower_m``,
``robot_length_upper_m``, ``pressure_Pa``, ..., ``Y_Pa``, ...; ``measured_robot_length_m`` where DATA holds a
length the filter did not read) and ``track.png`` under ``--out``. Causal (the filter) by default; ``--smooth``
for the whole record.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from growjax.cli import loader, options
from growjax.cli.command import Process

NAME = "track"
HELP = "the length, pressure and parameters over time with their bands, from the rig's own sensors"
METHODS = ("extended", "unscented")
DEFAULT_RECORD = "track/rig0.csv"  # the data without DATA: a shipped record with the pump's sensors and the length
PROCESS = Process()


def _pairs(items, flag: str) -> dict:
    """``NAME=VALUE`` strings → {name: float}; ValueError naming a bad one."""
    out = {}
    for text in items:
        if "=" not in text:
            raise ValueError(f"{flag} expects NAME=VALUE, got {text!r}")
        name, value = (s.strip() for s in text.split("=", 1))
        try:
            out[name] = float(value)
        except ValueError:
            raise ValueError(f"{flag} {name}: {value!r} is not a number") from None
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The shared options, ``--quiet`` and the command's own."""
    options.shared(parser, NAME, default_data=f"a shipped 3 s record of the pump's sensors, {DEFAULT_RECORD}")
    options.quiet(parser)
    options.add(parser, (options.TOLERANCE,))
    options.add(
        parser,
        (
            options.listed(
                "--sensors",
                default=["pressure", "syringe"],
                metavar="SENSOR[,...]",
                help=options.SENSORS_HELP,
            ),
        ),
    )
    parser.add_argument(
        "--noise",
        default="",
        metavar="SENSOR=SD,...",
        help="noise sd per sensor, SI (default: pressure 500 Pa, syringe 5e-6 m, flow 1e-9 m³/s, catheter and "
        "length 2e-4 m)",
    )
    parser.add_argument(
        "--estimate",
        default="Y",
        metavar="NAMES",
        help="parameters estimated as random walks, comma-separated ('' for none)",
    )
    parser.add_argument(
        "--prior-sd",
        action="append",
        default=[],
        metavar="NAME=SD",
        help="an estimated parameter's prior sd (relative; in its unit where it is 0; repeat) (default: 0.1)",
    )
    parser.add_argument(
        "--walk",
        action="append",
        default=[],
        metavar="NAME=SD",
        help="an estimated parameter's random walk, sd per √s (relative; repeat) (default: 0.01)",
    )
    parser.add_argument(
        "--discrepancy-size",
        type=_amplitude_and_time,
        default=None,
        metavar="AMPLITUDE_M,TIME_S",
        help="the length discrepancy a fit found: Matérn-3/2 amplitude (m) and time scale (s) (default: none)",
    )
    parser.add_argument(
        "--estimate-demand",
        action="store_true",
        help="the pressure demand (forward) or step count (inverse) was not recorded: estimate it as a random "
        "walk (default: off; the data's demand, or the published pulse)",
    )
    parser.add_argument(
        "--demand-walk",
        type=float,
        default=None,
        metavar="SD",
        help="the estimated demand's random walk, SI per √s (default: 3e5 Pa/√s, 30 steps/√s)",
    )
    parser.add_argument("--filter", choices=METHODS, default="extended", help="the filter (default: extended)")
    parser.add_argument("--smooth", action="store_true", help="the whole record's estimate, not the causal one")
    parser.add_argument(
        "--watch",
        action="store_true",
        help="watch the innovations for a sudden change (a CUSUM) and name it among the catalogue's effects (leak, "
        "tip load, fold, trapped air); the changes go in the summary, change_statistic and change_flag in the CSV "
        "(causal only)",
    )
    parser.add_argument(
        "--watch-threshold",
        type=float,
        default=None,
        metavar="H",
        help="the CUSUM's threshold, in sd of the innovations (default: 15)",
    )


def _amplitude_and_time(text: str) -> tuple[float, float]:
    """``AMPLITUDE_M,TIME_S`` → (amplitude m, time scale s)."""
    parts = [p.strip() for p in text.split(",")]
    try:
        amplitude, time_scale = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects AMPLITUDE_M,TIME_S, got {text!r}") from None
    return amplitude, time_scale


def model_of(args, params, noises: dict):
    """The state-space model the options describe (``params``: the nominal parameters; ``noises``: --noise parsed,
    {column: sd})."""
    import growjax as gj
    from growjax import track as tk
    from growjax.calibration import tolerance as tl
    from growjax.track import sensors as ts

    if getattr(args, "fidelity", "fast") != "fast":
        raise ValueError("track steps the fast configuration (--fidelity fast)")
    chosen = ts.sensor_set(",".join(args.sensors), noises)
    estimate = [n.strip() for n in args.estimate.split(",") if n.strip()]
    tolerance_texts = [t.strip() for t in args.tolerance]
    budget = tolerance_texts != ["none"]
    tolerances = dict(tl.parse(t) for t in tolerance_texts) if budget else {}
    discrepancy = None if args.discrepancy_size is None else tk.Discrepancy(*args.discrepancy_size)
    inputs = ()
    if args.estimate_demand:
        field = "pressure_demand" if args.drive == "forward" else "steps"
        inputs = (tk.InputState(field, walk=args.demand_walk),)
    if any(s.output == "catheter_length" for s in chosen):
        inputs += (tk.InputState("catheter_length"),)
    config = gj.Config(drive=args.drive, rtol=getattr(args, "rtol", None))
    return tk.state_space(
        params,
        drive=args.drive,
        sensors=chosen,
        estimate=estimate,
        prior_sd=_pairs(args.prior_sd, "--prior-sd"),
        walk=_pairs(args.walk, "--walk"),
        tolerances=tolerances,
        budget=budget,
        discrepancy=discrepancy,
        inputs=inputs,
        sample_interval=0.01,
        config=config,
    )


def _load(args):
    """(data path, experiment windowed to --t-end, parameters, their origin); a sensor's column may have empty
    cells (samples it did not take)."""
    import growjax as gj
    from growjax.data import datasets
    from growjax.data import experiment as ex

    data = loader.data_path(args.data, args.data_dir, default=datasets.dataset(DEFAULT_RECORD))
    exp = ex.read(data, catheter=args.catheter, sparse=ex.MEASURED_COLUMNS).window(args.t_end)
    loader.unused_columns_note(args, exp)
    recorded = loader.recorded_parameters(data)
    fixed = loader.fixed_parameters(args)
    params = (
        gj.replace(gj.reference(args.drive), **{**recorded, **fixed}) if recorded or fixed else gj.reference(args.drive)
    )
    gj.validate(params)
    return data, exp, params, {"recorded_beside_data": recorded, "fixed": fixed}


def run(args: argparse.Namespace) -> dict:
    """Track DATA; write ``track.csv`` and ``track.png`` under ``--out``; the JSON summary."""
    from growjax import track as tk
    from growjax.track import sensors as ts
    from growjax.track.figure import track_figure

    data, exp, params, origin = _load(args)
    noises = ts.parse_noise(args.noise)
    model = model_of(args, params, noises)
    method = tk.Unscented() if args.filter == "unscented" else tk.ExtendedKalman()
    if exp.time.size < 2:
        raise ValueError(f"{data} has fewer than two samples up to --t-end {args.t_end} s")
    if args.watch and args.smooth:
        raise ValueError("--watch is causal: drop --smooth")
    clock = time.perf_counter()
    watched = None
    if args.watch:
        cusum = tk.Cusum() if args.watch_threshold is None else tk.Cusum(threshold=args.watch_threshold)
        watched = tk.watch(exp, model, method=method, cusum=cusum)
        result, model = watched.track, watched.model
    else:
        result = tk.track(exp, model, method=method, smooth=args.smooth)
    wall = time.perf_counter() - clock
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scored = "robot_length_m" in exp and "robot_length_m" not in result.sensors
    extra = {"measured_robot_length_m": np.asarray(exp["robot_length_m"])} if scored else {}
    if watched is not None:
        extra.update(change_statistic=watched.statistic, change_flag=watched.flags())
    result.write_csv(out / "track.csv", extra)
    summary = _summary(args, data, exp, model, result, origin, wall)
    if watched is not None:
        summary["changes"] = watched.summary()
        summary["dismissed"] = [c.as_dict() for c in watched.dismissed]
    if scored:  # the band a reading falls in: widened by the length sensor's noise (--noise length=SD)
        noise = ts.sensor("length", noises.get("robot_length_m")).noise
        summary["score"] = {**result.score(exp["robot_length_m"], noise), "noise_m": noise}
    measured = {c: exp[c] for c in ("robot_length_m", "pressure_Pa") if c in exp}
    compare = None
    if args.estimate_demand and args.drive == "forward":
        compare = _demand_to_compare(exp, model)
    summary["csv"] = str(out / "track.csv")
    summary["figure"] = str(
        track_figure(result, out / "track.png", measured=measured, compare=compare, title=_title(data, result))
    )
    return summary


def _demand_to_compare(exp, model):
    """(label, time, demand) to draw beside an estimated demand: the data's own, else the published pulse train."""
    import jax

    import growjax as gj

    if "pressure_demand_Pa" in exp:
        return "recorded demand", exp.time, exp["pressure_demand_Pa"]
    return "published pulse train", exp.time, np.asarray(jax.vmap(gj.published_pulse())(exp.time))


def _title(data, result) -> str:
    kind = "smoothed" if result.smoothed else "filtered"
    return f"{Path(str(data)).name}: {', '.join(result.sensors)} ({result.method}, {kind})"


def _summary(args, data, exp, model, result, origin, wall) -> dict:
    """The JSON summary's body: what was read, the final estimates with their bands, the filter's consistency."""
    from growjax.track.result import asked, parameter_quantity

    final = {}
    for p in asked(model):
        q = parameter_quantity(model.params, p.name)
        est, lo, hi = result.band(q.column)
        final[p.name] = {"estimate": float(est[-1]), "lower_90": float(lo[-1]), "upper_90": float(hi[-1])}
    n = model.model_size
    rig = {
        p.name: {"relative_error": float(result.mean[-1, n + i]), "sd": float(np.sqrt(result.cov[-1, n + i, n + i]))}
        for i, p in enumerate(model.parameters)
        if p.tolerance
    }
    est, lo, hi = result.band("robot_length_m")
    steps = result.step_seconds[1:] if result.step_seconds.size > 1 else result.step_seconds
    return {
        "command": NAME,
        "data": str(data),
        "drive": args.drive,
        "parameters": origin,
        "sensors": {s.column: s.noise for s in model.sensors},
        "method": result.method,
        "smoothed": result.smoothed,
        "samples": int(result.time.size),
        "t_end_s": float(result.time[-1]),
        "final_length_m": {"estimate": float(est[-1]), "lower_90": float(lo[-1]), "upper_90": float(hi[-1])},
        "estimated": final,
        "rig": rig,
        "consistency": result.consistency(),
        "log_likelihood": result.log_likelihood,
        "step_ms_median": 1e3 * float(np.median(steps)),
        "first_step_s": float(result.step_seconds[0]),
        "wall_s": wall,
    }


def summary_lines(summary: dict) -> list[str]:
    """The human summary (mm, kPa)."""
    s = summary
    kind = "smoothed over the whole record" if s["smoothed"] else "filtered (causal)"
    fl = s["final_length_m"]
    lines = [
        f"track: {Path(s['data']).name}, {s['drive']} drive, sensors {', '.join(s['sensors'])}; {s['method']}, {kind}",
        f"  {s['samples']} samples to {s['t_end_s']:g} s; final length {1e3 * fl['estimate']:.2f} mm "
        f"[{1e3 * fl['lower_90']:.2f}, {1e3 * fl['upper_90']:.2f}] (90 %)",
    ]
    for name, e in s["estimated"].items():
        unit, scale = ("kPa", 1e-3) if name.endswith("yield_pressure") else ("", 1.0)
        lines.append(
            f"  {name} {scale * e['estimate']:.4g} [{scale * e['lower_90']:.4g}, {scale * e['upper_90']:.4g}] {unit}"
        )
    if s.get("score"):
        sc = s["score"]
        lines.append(
            f"  against the measured length (not read): RMSE {1e3 * sc['rmse_m']:.3f} mm, band (with its "
            f"{1e3 * sc.get('noise_m', 0.0):.2g} mm reading noise) covers {100 * sc['coverage_90']:.0f} % of "
            f"{sc['samples']} samples"
        )
    c = s["consistency"]
    if c["nis_per_reading"] is not None:
        lines.append(
            f"  innovations: NIS {c['nis_per_reading']:.2f} per reading (1 if honest), "
            f"{100 * c['nis_inside_90']:.0f} % inside their 90 % interval"
        )
    for c in s.get("changes", ()):
        lines.append(
            f"  change flagged at {c['flagged_s']:.2f} s (from {c['onset_s']:.2f} s, on {c['sensor']}): "
            f"{c['effect']}, {c['parameter']} {c['estimate']:.3g} ± {c['sd']:.2g}"
        )
    for c in s.get("dismissed", ()):
        lines.append(
            f"  flag at {c['flagged_s']:.2f} s dismissed: {c['effect']} of {c['estimate']:.3g}, too small to be a change"
        )
    if "changes" in s and not s["changes"]:
        lines.append("  no change flagged")
    lines.append(
        f"  step {s['step_ms_median']:.2f} ms (median) after {s['first_step_s']:.1f} s compiling; {s['wall_s']:.1f} s"
    )
    lines.append(f"  wrote {s['csv']}, {s['figure']}")
    return lines


__all__ = ["HELP", "METHODS", "NAME", "add_arguments", "model_of", "run", "summary_lines"]
