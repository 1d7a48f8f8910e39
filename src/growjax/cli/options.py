"""The options the commands share, declared once, and what they turn into: the parser's class (one-line errors,
defaults shown), the argument types, the shared option groups (data, drive, parameters, fidelity, seed, window,
output, progress, the likelihood's), and the configuration, tolerances, scored window and likelihood they name.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from growjax.cli.command import BAD_INPUT

DRIVES = ("forward", "inverse")
FIDELITIES = ("fast", "reference")


class Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's default shown, except where its help already says it."""

    def _get_help_string(self, action):
        if "(default:" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block) naming the problem and the valid values; the parsed
    arguments' ``given``: the options the command line spelled out (a value equal to the default included)."""

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


# -- argument types ---------------------------------------------------------------------------------------------


def effect_name(text: str) -> str:
    """An argparse type: a name of the effect catalogue (`growjax effects`)."""
    from growjax.model.effects import CATALOGUE

    if text not in CATALOGUE:
        raise argparse.ArgumentTypeError(f"unknown effect {text!r}; choose from {', '.join(CATALOGUE)}")
    return text


def count(minimum: int = 1):
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


def power_of_two(text: str) -> int:
    """An argparse type: a power of 2."""
    value = count(1)(text)
    if value & (value - 1):
        raise argparse.ArgumentTypeError(f"must be a power of 2 (128, 256, 512, ...), got {value}")
    return value


def positive(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def option(*flags: str, **settings) -> tuple:
    """One row of an options table: ``add_argument``'s flags and settings."""
    return flags, settings


def add(parser: argparse.ArgumentParser, table) -> None:
    """Add the options of ``table`` (rows of `option`) to ``parser``, in order."""
    for flags, settings in table:
        parser.add_argument(*flags, **settings)


# -- the shared groups ------------------------------------------------------------------------------------------

_DATA_HELP = (
    "experiment CSV, a folder with kings_ts.mat and lin_c_ts.mat, or 'mammobot': the public experiment, downloaded "
    "once, hash-checked and cached (default: the synthetic experiment shipped with growjax)"
)
_SOURCE = (
    option(
        "--no-catheter",
        dest="catheter",
        action="store_false",
        help="the experiment had no catheter in contact: its catheter length is taken as zero (without "
        "this, the data must have a catheter_length_m column) (default: off)",
    ),
    option(
        "--data-dir",
        default=None,
        metavar="DIR",
        help="a local copy of a named data set's files, hash-checked and used instead of downloading "
        "(default: $GROWJAX_DATA_DIR)",
    ),
)
_DRIVE = option(
    "--drive",
    choices=DRIVES,
    default="forward",
    help="forward: PID on the pressure with ideal torque sources; inverse: stepper motor and its step controller",
)
_PARAM = option(
    "--param",
    action="append",
    default=[],
    metavar="NAME=VALUE",
    help="fix a parameter, SI units (repeat; names as in `growjax params`); overrides values recorded beside the data",
)
_RUN = (
    option(
        "--rtol",
        type=positive,
        default=None,
        help="solver tolerance on the scaled states (None: 1e-4 fast, 1e-6 reference)",
    ),
    option("--seed", type=count(0), default=0, help="seed of every random choice"),
    option("--t-end", type=positive, default=10.0, metavar="S", help="end of the simulated window, s"),
)
_TOLERANCE_HELP = "relative standard uncertainty of a fixed parameter, e.g. Kp=0.1 {}"


def shared(
    parser: argparse.ArgumentParser,
    command: str,
    fidelity_default: str = "fast",
    fidelity_help: str = "",
    many: bool = False,
) -> None:
    """The options every workflow command takes: DATA (several with ``many``), the data's source, ``--drive``,
    ``--param``, ``--fidelity``, ``--rtol``, ``--seed``, ``--t-end``, ``--out`` (default ``out/COMMAND``) and
    ``--json``."""
    help_ = _DATA_HELP + ("; several, or a TOML manifest, are fitted jointly" if many else "")
    parser.add_argument("data", nargs="*" if many else "?", default=None, help=help_)
    add(parser, (*_SOURCE, _DRIVE, _PARAM))
    parser.add_argument(
        "--fidelity",
        choices=FIDELITIES,
        default=fidelity_default,
        help=fidelity_help or "configuration that solves the model: fast, or the reference network (slow)",
    )
    add(parser, _RUN)
    parser.add_argument(
        "--out", default=str(Path("out") / command), metavar="DIR", help="folder for the files the command writes"
    )
    json_option(parser, "write the full summary as JSON to FILE ('-': stdout)")


def json_option(parser: argparse.ArgumentParser, help_: str) -> None:
    """``--json FILE`` ('-': stdout)."""
    parser.add_argument("--json", metavar="FILE", default=None, help=help_)


def quiet(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress output."""
    parser.add_argument(
        "--quiet",
        action="store_true",
        help="no progress output (otherwise a bar on a terminal, a line every ~10 %% elsewhere, on stderr)",
    )


def likelihood(parser: argparse.ArgumentParser) -> None:
    """The likelihood's options that fit, posterior, discover and design share: ``--t-start``, ``--discrepancy``,
    ``--tolerance``."""
    parser.add_argument(
        "--t-start",
        type=float,
        default=None,
        metavar="S",
        help="score only the data from this time on, s (the model still runs from the start)",
    )
    parser.add_argument(
        "--discrepancy",
        choices=["matern32", "none"],
        default="matern32",
        help="matern32: the model plus a smooth Matérn-3/2 discrepancy plus sensor noise; none: "
        "independent noise around an exact model",
    )
    tolerance(parser, "(repeat; overrides the default budget of `growjax params`; 'none' drops the budget)")


def tolerance(parser: argparse.ArgumentParser, which: str) -> None:
    """``--tolerance NAME=REL`` (repeat); ``which``: what the tolerances do for this command."""
    parser.add_argument(
        "--tolerance", action="append", default=[], metavar="NAME=REL", help=_TOLERANCE_HELP.format(which)
    )


# -- what the options name --------------------------------------------------------------------------------------


def make_config(args, drive: str = "forward", **extra):
    """The `growjax.Config` named by the shared options (``--fidelity``, ``--rtol``, ``--t-end``); ``extra``:
    other fields."""
    import growjax as gj

    return gj.Config(fidelity=args.fidelity, drive=drive, t1=args.t_end, rtol=args.rtol, atol=args.rtol, **extra)


def tolerances_of(args) -> dict | None:
    """The ``tolerances`` of fit, posterior, discover and control from ``--tolerance``: {parameter: relative sd}
    on the default budget of ``--drive``'s reference; {} for ``--tolerance none``; None where none is given (the
    default budget for the likelihood's commands, the rig as it is for control)."""
    from growjax.calibration import tolerance as tl

    if not args.tolerance:
        return None
    if [t.strip().lower() for t in args.tolerance] == ["none"]:
        return {}
    from growjax.model import params as gp

    base = gp.reference(args.drive)
    return {**tl.default_budget(base), **dict(tl.parse(t) for t in args.tolerance)}


def scored_window(args, config) -> tuple[float, float]:
    """(t0, t1) s of the data scored: ``--t-start`` (default the configuration's start) to ``--t-end``;
    ValueError where it is empty."""
    t0 = config.t0 if args.t_start is None else args.t_start
    if not t0 < config.t1:
        raise ValueError(f"--t-start {t0} s must lie before --t-end {config.t1} s")
    return (t0, config.t1)


def likelihood_of(args):
    """The `growjax.calibration.Likelihood` the flags name: ``--discrepancy``, ``--tolerance`` (as
    `tolerances_of`) and, where the command has them, ``--rig`` and ``--rig-errors``."""
    from growjax.calibration import Likelihood

    return Likelihood(
        discrepancy=args.discrepancy,
        tolerances=tolerances_of(args),
        rig=getattr(args, "rig", None) or "inferred",
        rig_errors=getattr(args, "rig_errors", None) or "shared",
    )


__all__ = [
    "DRIVES",
    "FIDELITIES",
    "Formatter",
    "Parser",
    "add",
    "count",
    "effect_name",
    "json_option",
    "likelihood",
    "likelihood_of",
    "make_config",
    "option",
    "positive",
    "power_of_two",
    "quiet",
    "scored_window",
    "shared",
    "tolerance",
    "tolerances_of",
]
