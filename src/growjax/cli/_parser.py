"""The command line's parser: the shared options, each command's own, and one-line errors."""

from __future__ import annotations

import argparse
from pathlib import Path

BAD_INPUT = 2  # exit status for a bad option or file
DRIVES = ("forward", "inverse")
FIDELITIES = ("fast", "reference")


class _Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's default shown, except where its help already says it."""

    def _get_help_string(self, action):
        if "(default:" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block) naming the problem and the valid values; ``given``: the
    options the command line spelled out (a value equal to the default included)."""

    def error(self, message):
        self.exit(BAD_INPUT, f"{self.prog}: error: {message}\n")

    def parse_args(self, args=None, namespace=None):
        parsed = super().parse_args(args, namespace)
        if namespace is None:
            parsed.given = _given(self, args)
        return parsed


def _given(parser: argparse.ArgumentParser, args) -> set:
    """Destinations set on the command line ``args``: the parse again with every default suppressed."""
    actions = [a for p in _parsers(parser) for a in p._actions]
    saved = [a.default for a in actions]
    try:
        for a in actions:
            a.default = argparse.SUPPRESS
        return set(vars(argparse.ArgumentParser.parse_args(parser, args, argparse.Namespace())))
    finally:
        for a, d in zip(actions, saved):
            a.default = d


def _parsers(parser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _parsers(sub)


def _effect_name(text: str) -> str:
    from growjax.model.effects import CATALOGUE

    if text not in CATALOGUE:
        raise argparse.ArgumentTypeError(f"unknown effect {text!r}; choose from {', '.join(CATALOGUE)}")
    return text


def _count(minimum: int = 1):
    """An argparse type: an integer ≥ ``minimum``, else a one-line error naming the value."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    parse.__name__ = f"integer ≥ {minimum}"
    return parse


def _power_of_two(text: str) -> int:
    value = _count(1)(text)
    if value & (value - 1):
        raise argparse.ArgumentTypeError(f"must be a power of 2 (128, 256, 512, ...), got {value}")
    return value


def _positive(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _shared(
    p: argparse.ArgumentParser,
    command: str,
    fidelity_default: str = "fast",
    fidelity_help: str = "",
    many: bool = False,
):
    if many:
        p.add_argument(
            "data",
            nargs="*",
            default=None,
            help="experiment CSV, a folder with kings_ts.mat and lin_c_ts.mat, or 'mammobot': the public "
            "experiment, downloaded once, hash-checked and cached (default: the synthetic experiment "
            "shipped with growjax); several, or a TOML manifest, are fitted jointly",
        )
    else:
        p.add_argument(
            "data",
            nargs="?",
            default=None,
            help="experiment CSV, a folder with kings_ts.mat and lin_c_ts.mat, or 'mammobot': the public "
            "experiment, downloaded once, hash-checked and cached (default: the synthetic experiment "
            "shipped with growjax)",
        )
    p.add_argument(
        "--no-catheter",
        dest="catheter",
        action="store_false",
        help="the experiment had no catheter in contact: its catheter length is taken as zero (without "
        "this, the data must have a catheter_length_m column) (default: off)",
    )
    p.add_argument(
        "--data-dir",
        default=None,
        metavar="DIR",
        help="a local copy of a named data set's files, hash-checked and used instead of downloading "
        "(default: $GROWJAX_DATA_DIR)",
    )
    p.add_argument(
        "--drive",
        choices=DRIVES,
        default="forward",
        help="forward: PID on the pressure with ideal torque sources; inverse: stepper motor and its step controller",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="fix a parameter, SI units (repeat; names as in `growjax params`); overrides values recorded "
        "beside the data",
    )
    p.add_argument(
        "--fidelity",
        choices=FIDELITIES,
        default=fidelity_default,
        help=fidelity_help or "configuration that solves the model: fast, or the reference network (slow)",
    )
    p.add_argument(
        "--rtol",
        type=_positive,
        default=None,
        help="solver tolerance on the scaled states (None: 1e-4 fast, 1e-6 reference)",
    )
    p.add_argument("--seed", type=_count(0), default=0, help="seed of every random choice")
    p.add_argument("--t-end", type=_positive, default=10.0, metavar="S", help="end of the simulated window, s")
    p.add_argument(
        "--out", default=str(Path("out") / command), metavar="DIR", help="folder for the files the command writes"
    )
    p.add_argument("--json", metavar="FILE", default=None, help="write the full summary as JSON to FILE ('-': stdout)")


def _quiet(p: argparse.ArgumentParser):
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress output (otherwise a bar on a terminal, a line every ~10 %% elsewhere, on stderr)",
    )


def _likelihood(p: argparse.ArgumentParser):
    """The options of the likelihood that fit, posterior and discover share."""
    p.add_argument(
        "--t-start",
        type=float,
        default=None,
        metavar="S",
        help="score only the data from this time on, s (the model still runs from the start)",
    )
    p.add_argument(
        "--discrepancy",
        choices=["matern32", "none"],
        default="matern32",
        help="matern32: the model plus a smooth Matérn-3/2 discrepancy plus sensor noise; none: "
        "independent noise around an exact model",
    )
    _tolerance(p, "(repeat; overrides the default budget of `growjax params`; 'none' drops the budget)")


def _tolerance(p: argparse.ArgumentParser, which: str):
    p.add_argument(
        "--tolerance",
        action="append",
        default=[],
        metavar="NAME=REL",
        help=f"relative standard uncertainty of a fixed parameter, e.g. Kp=0.1 {which}",
    )


def tolerances_of(args):
    """The ``tolerances`` argument of fit, posterior, discover and control from ``--tolerance`` (None where it is
    not given: the default budget for the likelihood's commands, the rig as it is for control)."""
    from growjax.calibration import tolerance as tl

    if not args.tolerance:
        return None
    if [t.strip().lower() for t in args.tolerance] == ["none"]:
        return {}
    from growjax.model import params as gp

    base = gp.reference(args.drive)
    return {**tl.default_budget(base), **dict(tl.parse(t) for t in args.tolerance)}


def scored_window(args, config):
    """(t0, t1) s of the data scored: ``--t-start`` (default the configuration's start) to ``--t-end``."""
    t0 = config.t0 if args.t_start is None else args.t_start
    if not t0 < config.t1:
        raise ValueError(f"--t-start {t0} s must lie before --t-end {config.t1} s")
    return (t0, config.t1)


def build_parser():
    from growjax import __version__

    fmt = _Formatter
    parser = _Parser(
        prog="growjax",
        formatter_class=fmt,
        description="MAMMOBOT soft growing robot: simulate, sweep, fit, sample, discover, control, design",
    )
    parser.add_argument("--version", action="version", version=f"growjax {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    sim = sub.add_parser("simulate", formatter_class=fmt, help="simulate an experiment against its measured length")
    _shared(sim, "simulate")

    swp = sub.add_parser("sweep", formatter_class=fmt, help="Latin-hypercube sweep scored against the measured length")
    _shared(swp, "sweep")
    swp.add_argument("--n", type=_count(), default=500, help="number of parameter sets")
    swp.add_argument(
        "--range",
        action="append",
        default=[],
        metavar="NAME=LOW:HIGH[:log]",
        help="swept parameter and its range, SI units (repeat); none: the paper's n, Y, ext box",
    )
    swp.add_argument("--sobol", action="store_true", help="also compute Sobol indices of RMSE and final length")
    swp.add_argument(
        "--sobol-n", type=_power_of_two, default=256, help="Saltelli base points (a power of 2; runs = N·(d+2))"
    )
    swp.add_argument("--chunk-size", type=_count(), default=None, help="sets per compiled call (None: sized to memory)")

    swp.add_argument(
        "--resume",
        metavar="DIR",
        default=None,
        help="complete the interrupted sweep kept in DIR (its --out); its options are the recorded ones",
    )
    swp.add_argument(
        "--max-chunks",
        type=int,
        default=None,
        metavar="K",
        help="stop after K chunks, as an interrupt would (exit 3; complete with --resume)",
    )
    swp.add_argument(
        "--distributed",
        action="store_true",
        help="one process of several (jax.distributed, the cluster detected: SLURM, ...); process 0 writes the results",
    )
    swp.add_argument(
        "--coordinator",
        metavar="HOST:PORT",
        default=None,
        help="jax.distributed without a detected cluster: process 0's address (with --num-processes, --process-id)",
    )
    swp.add_argument("--num-processes", type=int, default=None, metavar="N", help="processes in all (--coordinator)")
    swp.add_argument("--process-id", type=int, default=None, metavar="I", help="this process, 0..N-1 (--coordinator)")
    _quiet(swp)

    fit = sub.add_parser("fit", formatter_class=fmt, help="least-squares fit to the measured length (and pressure)")
    _shared(fit, "fit", many=True)
    fit.add_argument(
        "--free",
        action="append",
        default=[],
        metavar="NAME[@SCOPE]",
        help="parameter to fit (repeat; none: Y). With several experiments, @robot, @rig or "
        "@experiment fits one per robot, rig or experiment, none one for all (none given: Y@robot)",
    )
    fit.add_argument("--starts", type=_count(), default=3, help="starts, from the best sets of a Latin hypercube")
    _quiet(fit)
    _likelihood(fit)
    fit.add_argument(
        "--rig",
        choices=["inferred", "fixed"],
        default="inferred",
        help="inferred: the toleranced rig parameters fitted beside the free ones, their tolerances "
        "as priors (the posterior's treatment); fixed: held nominal, each tolerance propagated "
        "as if the data said nothing of the rig (conservative)",
    )
    fit.add_argument(
        "--rig-errors",
        choices=["shared", "experiment"],
        default="shared",
        help="with several experiments: one set of rig errors per rig, shared by its experiments, or "
        "one per experiment (treats them as independent: over-confident on one rig)",
    )
    fit.add_argument(
        "--rig-tangents",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the rig inferred: the rig's errors are parameters of the model, their sensitivities its "
        "exact tangents, fitted with their priors before the discrepancy (default; reaches a rig "
        "far off nominal); --no-rig-tangents: the rig's secants from nominal, taken apart",
    )
    fit.add_argument(
        "--relinearise",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="with --no-rig-tangents: take the secants again where the data put the rig, until it "
        "settles (default); --no-relinearise: once, at nominal (faster; over-confident where the "
        "rig is off by a tolerance or more)",
    )

    post = sub.add_parser(
        "posterior",
        formatter_class=fmt,
        help="NUTS posterior of Y, ext, n (or Y, phi_L, n_L) and the noise; of a population of "
        "robots with --hierarchical",
    )
    _shared(post, "posterior", many=True)
    post.add_argument(
        "--hierarchical",
        default=None,
        metavar="NAME",
        help="a TOML manifest of several robots (or several files): each robot's NAME drawn from a "
        "log-normal population whose median and spread are sampled, the data entering through "
        "the set's joint fit; with the predictive for a new robot (default: off)",
    )
    post.add_argument(
        "--predict",
        default=None,
        metavar="CSV",
        help="with --hierarchical: the input (demand, catheter) of the new robot's experiment "
        "(default: the set's first experiment's)",
    )
    post.add_argument(
        "--law",
        choices=["reference", "lockhart"],
        default="reference",
        help="growth law: the published velocity term, or Lockhart's",
    )
    post.add_argument(
        "--emulate",
        action="store_true",
        help="sample through a validated emulator of the model (fast; worth it where the data leave "
        "directions flat, as ext and n of the published law)",
    )
    post.add_argument("--chains", type=_count(), default=4, help="NUTS chains")
    post.add_argument("--warmup", type=_count(0), default=500, help="warm-up draws per chain")
    post.add_argument("--samples", type=_count(), default=500, help="kept draws per chain")
    _quiet(post)
    _likelihood(post)

    dis = sub.add_parser(
        "discover",
        formatter_class=fmt,
        help="which catalogue effect the data need beyond the model (`growjax effects`)",
    )
    _shared(dis, "discover", many=True)
    dis.add_argument(
        "--candidates",
        nargs="+",
        metavar="EFFECT",
        type=_effect_name,
        default=None,
        help="catalogue effects to test (None: all of `growjax effects`)",
    )
    dis.add_argument("--workers", type=_count(), default=None, help="fits run at a time (None: one per CPU core)")
    _quiet(dis)
    _likelihood(dis)

    ctl = sub.add_parser("control", formatter_class=fmt, help="length control design: open-loop profile, feedback, MPC")
    _shared(
        ctl,
        "control",
        fidelity_default="reference",
        fidelity_help="configuration the design is evaluated on (designs use the fast one)",
    )
    ctl.add_argument(
        "--method",
        choices=["open-loop", "feedback", "mpc"],
        default="feedback",
        help="open-loop demand profile (or step schedule), tuned feedback, or MPC (forward drive)",
    )
    ctl.add_argument(
        "--robust", metavar="POSTERIOR.nc", default=None, help="tune on the cost averaged over draws of this posterior"
    )
    ctl.add_argument(
        "--draws",
        type=_count(),
        default=8,
        help="draws to tune on: of the posterior (--robust), of the rig (--tolerance)",
    )
    ctl.add_argument("--iterations", type=_count(), default=10, help="optimiser and tuning iterations")
    ctl.add_argument(
        "--microsteps", type=_count(), default=1, help="stepper driver microsteps (1: the full-step driver)"
    )
    _tolerance(
        ctl,
        "(repeat; the feedback design is then tuned on the cost averaged over --draws draws of the "
        "rig within the default budget of `growjax params` and these; none given: the rig as it is)",
    )
    _quiet(ctl)

    des = sub.add_parser(
        "design",
        formatter_class=fmt,
        help="design the next experiment: the forward drive's demand (or the stepper's schedule) "
        "that most shrinks the intervals",
    )
    _shared(des, "design")
    des.add_argument(
        "--for",
        dest="design_for",
        action="extend",
        nargs="+",
        default=[],
        metavar="NAME",
        help="parameters whose precision the design is for (repeat or list; none: Y)",
    )
    des.add_argument(
        "--discriminate",
        nargs="+",
        default=None,
        metavar="EFFECT",
        help="two rival catalogue effects A B: design to tell them apart (max min T, the expected "
        "2ΔlogL by which the data reject the wrong one) instead of for precision",
    )
    des.add_argument(
        "--size",
        nargs="+",
        type=float,
        default=None,
        metavar="SI",
        help="with --discriminate: the two effects' assumed sizes (default their moderate magnitudes)",
    )
    des.add_argument(
        "--fit-from",
        metavar="FIT.json",
        default=None,
        help="what is known: the JSON summary of `growjax fit --json` (default: fit DATA first)",
    )
    des.add_argument(
        "--sensors",
        choices=["length", "length,pressure"],
        default="length",
        help="what the next experiment records (length,pressure: the table also shows the length alone)",
    )
    des.add_argument(
        "--criterion",
        choices=["A", "D"],
        default="A",
        help="A: the sum of the relative variances; D: their generalised variance (log det)",
    )
    des.add_argument(
        "--next-drive",
        choices=DRIVES,
        default="forward",
        help="the drive of the experiment to design: forward (its pressure demand) or inverse (the "
        "stepper's step schedule, written as its desired length); DATA is read with --drive",
    )
    des.add_argument("--duration", type=_positive, default=10.0, metavar="S", help="length of the designed run, s")
    des.add_argument(
        "--knot-spacing",
        type=_positive,
        default=None,
        metavar="S",
        help="s between the demand's knots (forward drive; default 0.5)",
    )
    des.add_argument(
        "--p-max",
        type=_positive,
        default=None,
        metavar="PA",
        help="top of the demand, Pa (default: the sensed-pressure ceiling, the membrane limit × 0.9)",
    )
    des.add_argument("--random", type=_count(), default=64, help="random admissible inputs drawn and scored")
    des.add_argument("--starts", type=_count(), default=1, help="descents, from the best random inputs")
    des.add_argument(
        "--iterations",
        type=_count(),
        default=15,
        help="gradient steps per descent (the stepper: moves of its local search)",
    )
    des.add_argument("--draws", type=_count(2), default=32, help="draws of the rig and θ every design is checked on")
    des.add_argument(
        "--points",
        type=_count(),
        default=4,
        help="points of θ and the rig the criterion is averaged over (1: the local design at the estimate)",
    )
    des.add_argument(
        "--nonlinear-draws",
        type=_count(0),
        default=16,
        help="draws of the rig on which what the fit's linearised rig misses is measured (0: none)",
    )
    des.add_argument(
        "--pressure-noise",
        type=_positive,
        default=1e3,
        metavar="PA",
        help="sd of the pressure sensor's noise, Pa (with --sensors length,pressure)",
    )
    des.add_argument(
        "--max-pump-speed",
        type=_positive,
        default=None,
        metavar="M_S",
        help="limit of the pump platform's speed, m/s (the model's ideal torque source has none)",
    )
    des.add_argument(
        "--law",
        choices=["reference", "lockhart"],
        default="reference",
        help="growth law of what is known and of the design (lockhart: e.g. --for Y phi_L n_L)",
    )
    _quiet(des)
    _likelihood(des)

    from growjax.cli import track as track_command

    trk = sub.add_parser(track_command.NAME, formatter_class=fmt, help=track_command.HELP)
    _shared(trk, track_command.NAME)
    _quiet(trk)
    track_command.add_arguments(trk)

    par = sub.add_parser(
        "params", formatter_class=fmt, help="list the parameters: names, symbols, defaults, units, physical ranges"
    )
    par.add_argument("--drive", choices=DRIVES, default="forward", help="which drive's published parameter set")
    par.add_argument("--json", metavar="FILE", default=None, help="write the table as JSON to FILE ('-': stdout)")
    eff = sub.add_parser(
        "effects", formatter_class=fmt, help="list the effect catalogue: parameter, range, what separates each"
    )
    eff.add_argument("--json", metavar="FILE", default=None, help="write the catalogue as JSON to FILE ('-': stdout)")
    return parser
