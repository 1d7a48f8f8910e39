"""Command line: ``growjax COMMAND [DATA] [options]`` (``growjax --help``, ``growjax COMMAND --help``).

Every workflow command takes the same shared options (``--drive``, ``--param``, ``--t-end``, ``--out``, ``--json``,
``--config``; ``--fidelity`` and ``--seed`` where they apply; `growjax.cli.options`), prints a short summary in mm
and kPa, and exits with status 0 when its runs succeeded, 1 when a run failed or its files could not be written at
the end (the reason on stderr) and 2 for a bad option or file: every input, ``--out`` and ``--json`` included, is
checked before any compile or simulation, and refused with one line naming the option or file and the problem. A
command stopped by Ctrl-C or SIGTERM exits with 128 + the signal's number (130, 143), naming what it wrote; a sweep
keeps its chunks for ``growjax sweep --resume DIR`` (3 where ``--max-chunks`` stopped it). Progress goes to stderr:
bars on a terminal, a line every ~10 % elsewhere, none with ``--quiet``.

Each command is one module of this folder (`growjax.cli.command` says what it defines); `COMMANDS` lists them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from growjax.cli import (
    command,
    control,
    design,
    discover,
    effects,
    fit,
    loader,
    options,
    params,
    posterior,
    simulate,
    sweep,
    track,
)
from growjax.cli.command import BAD_INPUT, OK, RUN_FAILED, RunFailed, Stopped

# the commands, in the order `growjax --help` lists them
COMMANDS = (simulate, sweep, fit, posterior, discover, control, design, track, params, effects)


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
        The exit status: `OK`, `RUN_FAILED`, `BAD_INPUT`, 128 + a signal's number where Ctrl-C or SIGTERM stopped
        the command, or a stopped sweep's own.
    """
    import matplotlib

    matplotlib.use("Agg")  # the commands write figures to files
    args = build_parser().parse_args(argv)
    with command.terminate_as_interrupt():
        return _run(module_of(args.command), args)


def _bad_input_errors() -> tuple:
    """The exceptions that mean a bad option or file (exit 2)."""
    from growjax.data.datasets import DatasetError
    from growjax.data.experiment import ExperimentError

    return (ExperimentError, ValueError, FileNotFoundError, DatasetError)


def _run(cmd, args) -> int:
    """Check the outputs, run ``cmd`` on ``args``, report; the exit status (see `main`)."""
    import numpy as np

    def say(text: str) -> None:
        print(f"growjax {args.command}: {text}", file=sys.stderr)

    try:
        command.check_outputs(args)
        if cmd.PROCESS.workflow:
            loader.check_options(args)
    except ValueError as err:
        say(f"error: {err}")
        return BAD_INPUT
    before = command.outputs_now(args)
    status, failure = OK, None
    try:
        cmd.PROCESS.apply(args)
        summary = cmd.run(args)
    except np.linalg.LinAlgError:  # a ValueError, but a failure of the computation, not of the input
        raise
    except _bad_input_errors() as err:
        say(f"error: {err}")
        return BAD_INPUT
    except RunFailed as failed:
        summary, status, failure = failed.summary, RUN_FAILED, str(failed)
        summary["failure"] = failure
    except Stopped as stop:
        say(str(stop))
        return stop.status
    except KeyboardInterrupt as stop:
        say(command.interrupted_line(args, before, stop))
        return command.interrupted_status(stop)
    except OSError as err:  # a write that failed during the run: disk full, permissions changed
        say(f"failed: {_write_failure(err)}; {_kept(args, before)}")
        return RUN_FAILED
    if summary.get("process_index", 0):  # a worker of a distributed sweep: process 0 reports
        return status
    to_stdout = getattr(args, "json", None) == "-"
    if cmd.PROCESS.workflow or not to_stdout:  # a workflow's lines even with --json - (on stderr)
        print("\n".join(cmd.summary_lines(summary)), file=sys.stderr if to_stdout else sys.stdout)
    try:
        _write_json(summary, getattr(args, "json", None))
    except OSError as err:
        say(f"failed: the JSON summary: {_write_failure(err)}; {_kept(args, before)}")
        return RUN_FAILED
    if failure:
        say(f"failed: {failure}")
    return status


def _write_failure(err: OSError) -> str:
    """What could not be written, and why (one line)."""
    where = f" {err.filename}" if err.filename else ""
    return f"could not write{where} ({err.strerror or err})"


def _kept(args, before: dict) -> str:
    files = command.written(args, before)
    return f"kept {', '.join(files)}" if files else "nothing was written"


__all__ = ["BAD_INPUT", "COMMANDS", "OK", "RUN_FAILED", "build_parser", "main", "module_of", "summary_lines"]


if __name__ == "__main__":
    sys.exit(main())
