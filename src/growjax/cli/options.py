"""The options the commands share, declared once, and what they turn into: the argument types (counts, numbers,
comma-separated lists), the options tables and the shared option groups (data, drive, parameters, fidelity, seed,
window, output, progress, the likelihood's), and the configuration, tolerances, scored window and likelihood they
name. The parser itself (`Parser`, `Formatter`: one-line errors, real defaults, rare options, ``--config``) is
`growjax.cli.parser`'s, re-exported here.

One flag has one meaning in every command: a shared option is one row of this module, its help the same wherever
it appears. A list option takes comma-separated values in one argument and may be repeated (``--free Y,ext`` is
``--free Y --free ext``); none takes several space-separated values, so none can swallow a DATA placed after it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from growjax.cli.parser import RARE_TITLE, Formatter, Listed, Parser, is_rare, subparsers

DRIVES = ("forward", "inverse")
FIDELITIES = ("fast", "reference")


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


def number(text: str) -> float:
    """An argparse type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if value != value or abs(value) == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def one_of(*values: str):
    """An argparse type: one of ``values``, else a one-line error listing them."""

    def parse(text: str) -> str:
        if text not in values:
            raise argparse.ArgumentTypeError(f"invalid choice {text!r} (choose from {', '.join(values)})")
        return text

    parse.__name__ = "choice"
    return parse


def comma_list(item=str):
    """An argparse type: comma-separated values, each of type ``item``; a list (an empty item is an error)."""

    def parse(text: str) -> list:
        parts = [p.strip() for p in text.split(",")]
        if not all(parts):
            raise argparse.ArgumentTypeError(f"{text!r} has an empty item (give NAME,NAME,...)")
        return [item(p) for p in parts]

    parse.__name__ = "comma-separated list"
    return parse


def supported(command: str, values: tuple, why: str):
    """An argparse type for a choice the command takes only some values of: ``why`` says why the others are
    refused."""

    def parse(text: str) -> str:
        if text not in values:
            raise argparse.ArgumentTypeError(f"growjax {command} takes {' or '.join(values)} only: {why}")
        return text

    parse.__name__ = "choice"
    return parse


# -- options tables ---------------------------------------------------------------------------------------------


def option(*flags: str, **settings) -> tuple:
    """One row of an options table: ``add_argument``'s flags and settings; ``rare=True`` hides it from
    ``--help`` (``--help-all`` shows it)."""
    return flags, settings


SENSORS_HELP = (
    "the sensors read, comma-separated (design: length, pressure, those the next experiment records, the table "
    "also showing the length alone; track: pressure, syringe, flow, catheter, length, their columns on the data page)"
)


def listed(*flags: str, item=str, **settings) -> tuple:
    """One row of a list option: comma-separated values of type ``item``, the option repeatable."""
    return option(*flags, action=Listed, type=comma_list(item), **settings)


def rare(row: tuple) -> tuple:
    """The options-table ``row`` marked rare in the command that adds it."""
    flags, settings = row
    return flags, {**settings, "rare": True}


def add(parser: argparse.ArgumentParser, table) -> None:
    """Add the options of ``table`` (rows of `option`) to ``parser``, in order."""
    for flags, settings in table:
        settings = dict(settings)
        rare = settings.pop("rare", False)
        action = parser.add_argument(*flags, **settings)
        action.help = settings.get("help")  # argparse adds its own default text to some actions
        action.rare = rare


def hide(parser: argparse.ArgumentParser, *flags: str) -> None:
    """Mark the options ``flags`` of ``parser`` rare in this command (hidden from ``--help``)."""
    for action in parser._actions:
        if set(action.option_strings) & set(flags):
            action.rare = True
    missing = set(flags) - {s for a in parser._actions for s in a.option_strings}
    if missing:
        raise ValueError(f"no such options to hide: {sorted(missing)}")


def common(parser: argparse.ArgumentParser, name: str) -> None:
    """What every command takes besides its own options: ``--config``; and its usage line."""
    add(parser, (CONFIG,))
    data = {a.nargs for a in parser._actions if a.dest == "data"}
    shown = " [DATA ...]" if "*" in data else " [DATA]" if data else ""
    parser.usage = f"growjax {name}{shown} [options]"


# -- the shared options -----------------------------------------------------------------------------------------

_DATA_HELP = (
    "experiment CSV, a folder with the rig's MATLAB files (kings_ts.mat, lin_c_ts.mat), or 'mammobot': the public "
    "experiment, downloaded once, hash-checked and cached"
)
_DATA_DEFAULT = " (default: the synthetic experiment shipped with growjax)"
NO_CATHETER = option(
    "--no-catheter",
    dest="catheter",
    action="store_false",
    help="the experiment had no catheter in contact: its catheter length is taken as zero (without this, the data "
    "must have a catheter_length_m column)",
)
DATA_DIR = option(
    "--data-dir",
    default=None,
    metavar="DIR",
    rare=True,
    help="a local copy of a named data set's files, hash-checked and used instead of downloading "
    "(default: $GROWJAX_DATA_DIR, else downloaded)",
)
DRIVE = option(
    "--drive",
    choices=DRIVES,
    default="forward",
    help="the drive: forward: PID on the pressure with ideal torque sources; inverse: the stepper motor and its "
    "step controller",
)
PARAM = listed(
    "--param",
    default=[],
    metavar="NAME=VALUE[,...]",
    help="fix parameters, SI units (names as in `growjax params`); overrides values recorded beside the data "
    "(default: none)",
)
FIDELITY = option(
    "--fidelity",
    choices=FIDELITIES,
    default="fast",
    help="the configuration the command's model runs in: fast, or the reference network (slow)",
)
RTOL = option(
    "--rtol",
    type=positive,
    default=None,
    metavar="X",
    rare=True,
    help="solver tolerance on the scaled states (default: 1e-4 fast, 1e-6 reference)",
)
SEED = option("--seed", type=count(0), default=0, metavar="N", help="seed of every random choice")
T_END = option("--t-end", type=positive, default=10.0, metavar="S", help="end of the simulated window, s")
JSON = option(
    "--json", metavar="FILE", default=None, help="write the full summary as JSON to FILE ('-': stdout) (default: none)"
)
QUIET = option(
    "--quiet",
    action="store_true",
    help="no progress output (otherwise a bar on a terminal, a line every ~10 %% elsewhere, on stderr)",
)
CONFIG = option(
    "--config",
    metavar="FILE.toml",
    default=None,
    help="options from a TOML file: keys are the long options without the dashes, a [COMMAND] table holds one "
    "command's; the command line overrides the file (default: none)",
)
PRESSURE_NOISE = option(
    "--pressure-noise", type=positive, default=1e3, metavar="PA", help="sd of the pressure sensor's noise, Pa"
)
LAW = option(
    "--law",
    choices=["reference", "lockhart"],
    default="reference",
    help="growth law: reference (the published velocity term) or lockhart (Lockhart's; its rate phi_L and "
    "exponent n_L)",
)
SCOUT_HELP = "points drawn at random and scored before the local searches, which start from the best of them"
STARTS = "local searches, each from one of the best points of the scout (--scout)"


def shared(
    parser: argparse.ArgumentParser,
    command: str,
    *,
    many: bool = False,
    fidelity: bool = True,
    rtol: bool = True,
    seed: bool = True,
    default_data: str | None = None,
) -> None:
    """The options every command that reads data takes: DATA (several with ``many``), ``--no-catheter``,
    ``--data-dir``, ``--drive``, ``--param``, ``--fidelity`` (where the command's model runs in a configuration
    of its choosing), ``--rtol`` (where it sets the solver's tolerance), ``--seed`` (where it draws), ``--t-end``,
    ``--out`` (default ``out/COMMAND``) and ``--json``; ``default_data`` says what the command reads without DATA
    where that is not the shipped synthetic experiment."""
    help_ = _DATA_HELP + ("; several files, or a TOML manifest, for several experiments" if many else "")
    default = _DATA_DEFAULT if default_data is None else f" (default: {default_data})"
    parser.add_argument("data", nargs="*" if many else "?", default=None, metavar="DATA", help=help_ + default)
    rows = [NO_CATHETER, DATA_DIR, DRIVE, PARAM]
    rows += [FIDELITY] if fidelity else []
    rows += [RTOL] if rtol else []
    rows += [SEED] if seed else []
    out = option(
        "--out",
        default=str(Path("out") / command),
        metavar="DIR",
        help="folder for the files the command writes",
    )
    add(parser, (*rows, T_END, out, JSON))


def quiet(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress output."""
    add(parser, (QUIET,))


def json_option(parser: argparse.ArgumentParser) -> None:
    """``--json FILE`` ('-': stdout)."""
    add(parser, (JSON,))


def likelihood(
    parser: argparse.ArgumentParser,
    command: str,
    rig: tuple = ("inferred", "fixed"),
    rig_errors: tuple | None = ("shared", "experiment"),
) -> None:
    """The likelihood's options that fit, posterior, discover and design share: ``--t-start``, ``--discrepancy``,
    ``--tolerance``, ``--rig`` (``rig``: the treatments the command supports; the other refused with one line)
    and, where the command reads several experiments, ``--rig-errors`` (``rig_errors``: likewise)."""
    rows = [
        option(
            "--t-start",
            type=number,
            default=None,
            metavar="S",
            help="score only the data from this time on, s (the model still runs from the start) "
            "(default: the start of the simulated window)",
        ),
        option(
            "--discrepancy",
            choices=["matern32", "none"],
            default="matern32",
            help="the residual model: matern32: the model plus a smooth Matérn-3/2 discrepancy plus sensor noise; "
            "none: independent noise around an exact model",
        ),
        TOLERANCE,
        option(
            "--rig",
            choices=["inferred", "fixed"],
            type=supported(command, rig, "the rig's tolerances enter its likelihood as priors, the rig inferred"),
            default=rig[0],
            help="how the rig's tolerances enter: inferred: the toleranced rig parameters fitted beside the free "
            "ones, their tolerances as priors; fixed: held nominal, each tolerance propagated as if the data said "
            "nothing of the rig (conservative)",
        ),
    ]
    if rig_errors is not None:
        why = "its experiments share one set of rig errors per rig"
        rows.append(
            option(
                "--rig-errors",
                choices=["shared", "experiment"],
                type=supported(command, rig_errors, why),
                default=rig_errors[0],
                rare=True,
                help="with several experiments: one set of rig errors per rig, shared by its experiments, or one "
                "per experiment (treats them as independent: over-confident on one rig)",
            )
        )
    add(parser, rows)


TOLERANCE = listed(
    "--tolerance",
    default=[],
    metavar="NAME=REL[,...]",
    help="the rig's tolerance budget: relative standard uncertainties of fixed parameters, e.g. Kp=0.1, on top "
    "of the default budget of `growjax params`; 'none' drops the budget (default: the default budget)",
)


# -- what the options name --------------------------------------------------------------------------------------


def make_config(args, drive: str = "forward", **extra):
    """The `growjax.Config` named by the shared options (``--fidelity``, default fast; ``--rtol``; ``--t-end``);
    ``extra``: other fields."""
    import growjax as gj

    rtol = getattr(args, "rtol", None)
    fidelity = getattr(args, "fidelity", "fast")
    return gj.Config(fidelity=fidelity, drive=drive, t1=args.t_end, rtol=rtol, atol=rtol, **extra)


def tolerances_of(args) -> dict | None:
    """The ``tolerances`` of ``--tolerance``: {parameter: relative sd} on the default budget of ``--drive``'s
    reference; {} for ``--tolerance none``; None where none is given (the default budget)."""
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
    "SENSORS_HELP",
    "CONFIG",
    "DATA_DIR",
    "DRIVE",
    "DRIVES",
    "FIDELITIES",
    "FIDELITY",
    "JSON",
    "LAW",
    "NO_CATHETER",
    "PARAM",
    "PRESSURE_NOISE",
    "QUIET",
    "RARE_TITLE",
    "RTOL",
    "SCOUT_HELP",
    "SEED",
    "STARTS",
    "TOLERANCE",
    "T_END",
    "Formatter",
    "Listed",
    "Parser",
    "add",
    "comma_list",
    "common",
    "count",
    "effect_name",
    "hide",
    "is_rare",
    "json_option",
    "likelihood",
    "likelihood_of",
    "listed",
    "make_config",
    "number",
    "one_of",
    "option",
    "positive",
    "power_of_two",
    "quiet",
    "rare",
    "scored_window",
    "shared",
    "subparsers",
    "supported",
    "tolerances_of",
]
