"""Command line: ``growjax COMMAND [DATA] [options]`` (``growjax --help``, ``growjax COMMAND --help``).

Every workflow command takes the same shared options (``--drive``, ``--param``, ``--t-end``, ``--out``, ``--json``,
``--config``; ``--fidelity`` and ``--seed`` where they apply; `growjax.cli.options`), prints a short summary in mm
and kPa, and exits with status 0 when its runs succeeded, 1 when a run failed (the reason on stderr) and 2 for a
bad option or file. A sweep stopped before its end (its chunks kept for ``growjax sweep --resume DIR``) exits with
128 + the signal's number (130 for SIGINT, 143 for SIGTERM), or 3 where ``--max-chunks`` stopped it. Progress goes
to stderr: bars on a terminal, a line every ~10 % elsewhere, none with ``--quiet``.

Each command is one module of this folder (`growjax.cli.command` says what it defines); `COMMANDS` lists them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from growjax.cli import control, design, discover, effects, fit, options, params, posterior, simulate, sweep
from growjax.cli.command import BAD_INPUT, OK, RUN_FAILED, RunFailed, Stopped

# the commands, in the order `growjax --help` lists them
COMMANDS = (simulate, sweep, fit, posterior, discover, control, design, params, effects)


def module_of(name: str):
    """The module of the command ``name``."""
    return next(c for c in COMMANDS if c.NAME == name)


def build_parser() -> options.Parser:
    """The parser of ``growjax``: one sub-command per module of `COMMANDS`."""
    from growjax import __version__

    parser = options.Parser(
        prog="growjax",
        formatter_class=options.Formatter,
        description="MAMMOBOT soft growing robot: simulate, sweep, fit, sample, discover, control, design",
    )
    parser.add_argument("--version", action="version", version=f"growjax {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=options.Parser)
    for c in COMMANDS:
        command = sub.add_parser(c.NAME, formatter_class=options.Formatter, help=c.HELP, description=c.HELP)
        c.add_arguments(command)
        options.common(command, c.NAME)
    return parser


def summary_lines(summary: dict) -> list[str]:
    """A few lines for the terminal, in mm and kPa, by the summary's command (its JSON where none is named)."""
    for c in COMMANDS:
        if c.NAME == summary.get("command"):
            return c.summary_lines(summary)
    return [json.dumps(summary, default=str)]


def _write_json(summary: dict, where: str | None) -> None:
    if not where:
        return
    text = json.dumps({k: v for k, v in summary.items() if k != "text"}, indent=2, default=str)
    if where == "-":
        print(text)
    else:
        Path(where).parent.mkdir(parents=True, exist_ok=True)
        Path(where).write_text(text + "\n")


def main(argv=None) -> int:
    """Run ``growjax`` on the command line ``argv`` (default ``sys.argv[1:]``).

    Returns:
        The exit status: `OK`, `RUN_FAILED`, `BAD_INPUT`, or a stopped command's own.
    """
    import matplotlib

    matplotlib.use("Agg")  # the commands write figures to files
    args = build_parser().parse_args(argv)
    cmd = module_of(args.command)
    to_stdout = getattr(args, "json", None) == "-"
    human = sys.stderr if to_stdout else sys.stdout
    if not cmd.PROCESS.workflow:
        summary = cmd.run(args)
        _write_json(summary, getattr(args, "json", None))
        if not to_stdout:
            print("\n".join(cmd.summary_lines(summary)), file=human)
        return OK
    cmd.PROCESS.apply(args)
    import numpy as np

    from growjax.data.datasets import DatasetError
    from growjax.data.experiment import ExperimentError

    status, failure = OK, None
    try:
        summary = cmd.run(args)
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
    _write_json(summary, getattr(args, "json", None))
    print("\n".join(cmd.summary_lines(summary)), file=human)
    if failure:
        print(f"growjax {args.command}: failed: {failure}", file=sys.stderr)
    return status


__all__ = ["BAD_INPUT", "COMMANDS", "OK", "RUN_FAILED", "build_parser", "main", "module_of", "summary_lines"]


if __name__ == "__main__":
    sys.exit(main())
