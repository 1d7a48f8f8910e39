"""``growjax design [DATA]``: what is known (a fit of DATA, or ``--fit-from``), then the next experiment's input
that most shrinks the intervals (the forward drive's demand, or the stepper's schedule), or that best tells two
rival effects apart (``--discriminate A,B``); writes design.csv, design.png and summary.json."""

from __future__ import annotations

import json
import time
from pathlib import Path

from growjax.cli import loader, options
from growjax.cli._summary import data_name, kpa, mm, origin_lines, value
from growjax.cli.command import Process, note, out_dir
from growjax.cli.options import DRIVES, LAW, PRESSURE_NOISE, count, listed, option, positive, rare

NAME = "design"
HELP = (
    "design the next experiment: the forward drive's demand (or the stepper's schedule) that most shrinks the intervals"
)
PROCESS = Process()
SENSORS = ("length", "pressure")  # what an experiment designed for may record, in the design's order
OPTIONS = (
    listed(
        "--for",
        dest="design_for",
        default=[],
        metavar="NAME[,...]",
        help="parameters whose precision the design is for (default: Y)",
    ),
    listed(
        "--discriminate",
        default=None,
        metavar="EFFECT,EFFECT",
        help="two rival catalogue effects: design to tell them apart (max min T, the expected 2ΔlogL by which the "
        "data reject the wrong one) instead of for precision (default: off)",
    ),
    listed(
        "--size",
        item=options.number,
        default=None,
        metavar="SI,SI",
        help="with --discriminate: the two effects' assumed sizes, SI (default: their moderate magnitudes)",
    ),
    option(
        "--fit-from",
        metavar="FIT.json",
        default=None,
        help="what is known: the JSON summary of `growjax fit --json` (default: a fit of DATA)",
    ),
    listed(
        "--sensors",
        item=options.one_of(*SENSORS),
        default=["length"],
        metavar="SENSOR[,...]",
        help=options.SENSORS_HELP,
    ),
    option(
        "--criterion",
        choices=["A", "D"],
        default="A",
        help="A: the sum of the relative variances; D: their generalised variance (log det)",
    ),
    option(
        "--next-drive",
        choices=DRIVES,
        default="forward",
        help="the drive of the experiment to design: forward (its pressure demand) or inverse (the "
        "stepper's step schedule, written as its desired length); DATA is read with --drive",
    ),
    option("--duration", type=positive, default=10.0, metavar="S", help="length of the designed run, s"),
    option(
        "--p-max",
        type=positive,
        default=None,
        metavar="PA",
        help="top of the demand, Pa (default: the sensed-pressure ceiling, the membrane limit × 0.9)",
    ),
    option(
        "--knot-spacing",
        type=positive,
        default=None,
        metavar="S",
        rare=True,
        help="s between the demand's knots (forward drive) (default: 0.5)",
    ),
    option("--scout", type=count(), default=64, metavar="N", rare=True, help=options.SCOUT_HELP),
    option("--starts", type=count(), default=1, metavar="K", rare=True, help=options.STARTS),
    option(
        "--descent-steps",
        type=count(),
        default=15,
        metavar="N",
        rare=True,
        help="steps of each local search: Adam's on the demand, moves on the stepper's schedule",
    ),
    option(
        "--check-draws",
        type=count(2),
        default=32,
        metavar="N",
        rare=True,
        help="draws of the rig and θ every design is checked on",
    ),
    option(
        "--criterion-points",
        type=count(),
        default=4,
        metavar="N",
        rare=True,
        help="points of θ and the rig the criterion is averaged over (1: the local design at the estimate)",
    ),
    option(
        "--nonlinear-draws",
        type=count(0),
        default=16,
        metavar="N",
        rare=True,
        help="draws of the rig on which what the fit's linearised rig misses is measured (0: none)",
    ),
    rare(PRESSURE_NOISE),
    option(
        "--max-pump-speed",
        type=positive,
        default=None,
        metavar="M_S",
        rare=True,
        help="limit of the pump platform's speed, m/s (the model's ideal torque source has none) (default: none)",
    ),
    rare(LAW),
)
# the shared options design's --help leaves to --help-all (it shows at most 15)
HIDDEN = ("--no-catheter", "--seed", "--t-end", "--json", "--quiet", "--t-start", "--discrepancy", "--rig")


def add_arguments(parser) -> None:
    """The shared options (no ``--fidelity``, ``--rtol``: design runs the fast configuration), the design's,
    ``--quiet``, the likelihood's (of the fit of DATA); those of `HIDDEN` rare here."""
    options.shared(parser, NAME, fidelity=False, rtol=False)
    options.add(parser, OPTIONS)
    options.quiet(parser)
    options.likelihood(parser, NAME, rig=("inferred",), rig_errors=None)
    options.hide(parser, *HIDDEN)


def run(args) -> dict:
    """What is known, then the design; writes its files and returns the summary."""
    from growjax import design as gd
    from growjax.model import params as gp
    from growjax.model.limits import limits

    _check(args)
    data = loader.load(args, growth_law=args.law)
    base = data.base()
    names = tuple(dict.fromkeys(gp.resolve_name(base, n) for n in (args.design_for or ["Y"])))
    base_next = base if args.next_drive == args.drive else data.base(args.next_drive)
    lim = limits(base_next, max_pump_speed=args.max_pump_speed)
    if args.next_drive == "inverse":
        space = gd.stepper_space(base_next, args.duration, data.experiment)
    else:
        space = gd.demand_space(args.duration, lim, data.experiment, p_max=args.p_max, knot_spacing=args.knot_spacing)
    known, known_status = _known(args, data, base, names)
    if base_next is not base:
        known = known.on(base_next)  # θ as fitted, on the next experiment's drive
    result = _design(args, known, space, lim, names)
    out = out_dir(args)
    csv = space.write_csv(out / "design.csv", result.x)
    figure = gd.design_figure(result, out / "design.png")
    summary = {
        "command": NAME,
        "data": str(data.path),
        "data_drive": args.drive,
        "fixed_parameters": data.origin,
        "growth_law": args.law,
        "known_fit_status": known_status,
        **result.summary(),
        "design_csv": str(csv),
        "figure": str(figure),
        "summary_json": str(out / "summary.json"),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    return summary


def _check(args) -> None:
    """Refuse, before any work, options that do not go together (the rivals and their sizes as the workflow
    checks them, `growjax.design.discrimination.checked_pair`); the sensors in their order."""
    from growjax.design import discrimination as ddis

    if "length" not in args.sensors:
        raise ValueError(f"--sensors {','.join(args.sensors)}: the length is always recorded (length[,pressure])")
    args.sensors = [s for s in SENSORS if s in args.sensors]
    if args.discriminate is not None:
        ddis.checked_pair(args.discriminate, args.size, args.next_drive)
    if args.next_drive == "inverse" and (args.knot_spacing is not None or args.p_max is not None):
        raise ValueError(
            "--knot-spacing and --p-max shape the forward drive's demand; the stepper's schedule has "
            "neither (its steps are the controller's, at most one per period)"
        )
    if args.discriminate is not None:
        if args.design_for:
            raise ValueError("--for designs for precision, --discriminate to tell two effects apart: give one of them")
        if args.sensors != ["length"]:
            raise ValueError("--discriminate scores the length alone: drop --sensors")
    elif args.size is not None:
        raise ValueError("--size gives the effects' sizes of --discriminate")


# -- the workflow's calls ---------------------------------------------------------------------------------------


def _known(args, data, base, names):
    """(what is known (`growjax.design.Knowledge`), the status of the fit it comes from): ``--fit-from``'s saved
    fit, or a fit of ``names`` to DATA (`growjax.calibration.fit`)."""
    from growjax import calibration
    from growjax import design as gd
    from growjax.data import sets as xs

    likelihood = options.likelihood_of(args)
    if args.fit_from:
        known = gd.from_summary(args.fit_from, base, names, likelihood=likelihood)
        return known, _saved_status(args.fit_from)
    exp = data.experiment
    if "robot_length_m" not in exp:
        raise ValueError(f"{data.path} has no robot_length_m column to fit: give what is known with --fit-from")
    config = options.make_config(args, args.drive, adjoint="forward")
    exps = xs.ExperimentSet.single(
        exp,
        name=data.path.stem or "experiment",
        drive=args.drive,
        defaults=base,
        window=options.scored_window(args, config),
    )
    started = note(args, f"design: what is known, a fit of {', '.join(names)} to {data.path.name}")
    fitted = calibration.fit(exps, names, likelihood=likelihood, config=config, seed=args.seed)
    note(args, f"design: fitted in {time.perf_counter() - started:.1f} s")
    return gd.from_fit(fitted, base, likelihood=likelihood), fitted.status


def _saved_status(path) -> str | None:
    """The status a saved fit's JSON summary records (None where it records none)."""
    try:
        return json.loads(Path(path).read_text()).get("status")
    except (OSError, ValueError, AttributeError):
        return None


def _design(args, known, space, lim, names):
    """The design (`growjax.design.design`), or the discrimination design (`growjax.design.discriminate`)."""
    from growjax import design as gd

    if args.discriminate is not None:
        started = note(args, f"design: to tell {' from '.join(args.discriminate)}, {args.duration:g} s")
        result = gd.discriminate(
            known,
            space,
            args.discriminate,
            sizes=args.size,
            random=args.scout,
            starts=args.starts,
            iterations=args.descent_steps,
            n_draws=args.check_draws,
            seed=args.seed,
            limits=lim,
            progress=not args.quiet,
        )
    else:
        what = "step schedule" if args.next_drive == "inverse" else "demand"
        started = note(
            args,
            f"design: {args.criterion}-optimal {what} for {', '.join(names)}, "
            f"{args.duration:g} s, sensors {','.join(args.sensors)}",
        )
        result = gd.design(
            known,
            space,
            criterion={"A": gd.AOptimal, "D": gd.DOptimal}[args.criterion](),
            sensors=tuple(args.sensors),
            random=args.scout,
            starts=args.starts,
            iterations=args.descent_steps,
            n_draws=args.check_draws,
            seed=args.seed,
            points=args.criterion_points,
            pressure_noise=args.pressure_noise,
            limits=lim,
            nonlinear_draws=args.nonlinear_draws,
            progress=not args.quiet,
        )
    note(args, f"design: done in {time.perf_counter() - started:.1f} s")
    return result


# -- the summary for people -------------------------------------------------------------------------------------


def summary_lines(s: dict) -> list[str]:
    """The design's space, the table (precision, or the rivals' T), the check over the draws, the random batch
    and the files."""
    names = s["parameters"]
    if s.get("discrimination"):
        a, b = s["discrimination"]["effects"]
        lines = [
            f"design: {data_name(s)}, to tell {a} from {b}, {s['duration_s']:g} s, demand in 0–{kpa(s['p_max_Pa'])} "
            f"on knots every {s['knot_spacing_s']:g} s",
            *origin_lines(s["fixed_parameters"]),
            *_known_lines(s),
            *_discrimination_rows(s),
        ]
        return lines + _tail(s)
    if s.get("drive") == "inverse":
        space = (
            f"the stepper's schedule, up to one step of {mm(s['metres_per_step'])} of length every "
            f"{1 / s['controller_rate_Hz']:.3g} s"
        )
    else:
        space = f"demand in 0–{kpa(s['p_max_Pa'])} on knots every {s['knot_spacing_s']:g} s"
    lines = [
        f"design: {data_name(s)}, {s['criterion']}-optimal for {', '.join(names)}, {s['duration_s']:g} s, {space}",
        *origin_lines(s["fixed_parameters"]),
        *_known_lines(s),
    ]
    head = f"  {'input':26s} {'sensors':16s}" + "".join(f" {n.split('.')[-1][:14]:>14s} sd  90 % width" for n in names)
    lines += [head + "   alone sd"]
    for row in s["table"]:
        cells = ""
        for n in names:
            p = row["parameters"][n]
            cells += f" {100 * p['sd_log']:16.2f} %  {value(n, p['width_90']):>10s}"
        alone = ", ".join(f"{100 * row['parameters'][n]['sd_log_alone']:.2f} %" for n in names)
        lines.append(f"  {row['input']:26s} {'+'.join(row['sensors']):16s}{cells}   {alone}")
    return lines + _tail(s)


def _known_lines(s: dict) -> list[str]:
    """Where the fit of what is known did not converge: a line saying what the design rests on."""
    status = s.get("known_fit_status")
    if status in ("converged", None):
        return []
    return [
        f"  what is known comes from a fit that did not converge ({status}): the design rests on where its search "
        "stopped, not on estimates"
    ]


def _discrimination_rows(s: dict) -> list[str]:
    d = s["discrimination"]
    a, b = d["effects"]
    keys = (f"{a} real, {b} fitted", f"{b} real, {a} fitted")
    lines = [
        "  T: the expected 2ΔlogL by which the data reject the wrong effect (linearised; sizes "
        + ", ".join(f"{p} = {v:g}" for p, v in zip(d["parameters"], d["sizes"]))
        + f"); separates where min T > {d['threshold']:.2f}, the discovery's threshold",
        f"  {'input':24s} {'T (' + a + ' real)':>30s} {'T (' + b + ' real)':>30s} {'min T':>9s}  expected to separate",
    ]
    for row in s["table"]:
        lines.append(
            f"  {row['input']:24s} {row['T'][keys[0]]:30.2f} {row['T'][keys[1]]:30.2f} {row['T_min']:9.2f}  "
            f"{'yes' if row['expected_to_separate'] else 'no'}"
        )
    return lines


def _tail(s: dict) -> list[str]:
    check, lim = s["checks"]["design"], s["limits"]
    lines = [
        f"  design over the draws: peak pressure {kpa(check['peak_pressure_Pa'])} (ceiling "
        f"{kpa(lim['pressure_ceiling_Pa'])}), peak length {mm(check['peak_length_m'])} (ceiling "
        f"{mm(lim['length_ceiling_m'])}): {'admissible' if check['admissible'] else 'NOT admissible'}"
    ]
    r = s["random"]
    undefined = r.get("criterion_undefined", 0)
    lines.append(
        f"  {r['admissible']} random admissible inputs (of {r['drawn']} drawn"
        + (f"; {undefined} with no criterion: the model failed or they inform nothing" if undefined else "")
        + f"); {s['wall_s']['total_s']:.0f} s"
    )
    lines.append(f"  wrote {s['design_csv']}, {s['figure']}, {s['summary_json']}")
    return lines


__all__ = ["HELP", "NAME", "OPTIONS", "PROCESS", "add_arguments", "run", "summary_lines"]
