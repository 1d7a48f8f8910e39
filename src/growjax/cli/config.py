"""``--config FILE.toml``: a command's options from a file, applied under the command line.

The file's top-level keys are long options without the dashes (``chunk-size = 100``, ``free = ["Y", "ext"]``,
``rig-tangents = false``); a ``[COMMAND]`` table (``[design]``) holds options for that command alone and wins over
the top level, so one file can serve several commands. A top-level key that another command takes but this one
does not is left to that command. An option the command line gives overrides the file's. A key no command takes,
a table that is no command, or a value of the wrong kind is an error naming the key and the file.
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

from growjax.cli.parser import Listed, subparsers

NOT_KEYS = ("help", "help-all", "config")  # long options that a file cannot set


def keys(parser: argparse.ArgumentParser) -> dict:
    """{key: its action} of ``parser``: each long option without the dashes."""
    return {s[2:]: a for a in parser._actions for s in a.option_strings if s.startswith("--") and s[2:] not in NOT_KEYS}


def read(path: Path) -> dict:
    """The TOML file ``path`` as a dict; ValueError (one line) where it is missing or not TOML."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ValueError(f"cannot read it ({err.strerror or err})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"not valid TOML ({err})") from None


def entries(table: dict, command: str, parsers: dict) -> dict:
    """{key: value} of ``table`` (a config file read) that apply to ``command`` (``parsers``: every command's
    parser by name); ValueError naming a key or table that none takes."""
    own = keys(parsers[command])
    everywhere = {k for p in parsers.values() for k in keys(p)}
    chosen = {}
    for key, value in table.items():
        if isinstance(value, dict):
            if key not in parsers:
                raise ValueError(f"unknown table [{key}] (tables name commands: {', '.join(parsers)})")
            continue
        if key in NOT_KEYS:
            raise ValueError(f"key {key!r}: --{key} is for the command line only")
        if key not in everywhere:
            raise ValueError(f"unknown key {key!r}: no growjax command has --{key}")
        if key in own:
            chosen[key] = value
    for key, value in table.get(command, {}).items():
        if key in NOT_KEYS:
            raise ValueError(f"key {key!r}: --{key} is for the command line only")
        if key not in own:
            raise ValueError(f"unknown key {key!r} in [{command}]: growjax {command} has no --{key}")
        chosen[key] = value
    return chosen


def tokens(key: str, value, action: argparse.Action) -> list[str]:
    """The command-line words that set ``key`` to the TOML ``value``; ValueError for a value of the wrong kind."""
    flag = "--" + key
    if action.nargs == 0:
        if not isinstance(value, bool):
            raise ValueError(f"{key} is a switch: give true or false, got {value!r}")
        if isinstance(action, argparse.BooleanOptionalAction):
            positive, negative = action.option_strings
            on = value if flag == positive else not value
            return [positive if on else negative]
        return [flag] if value else []
    values = value if isinstance(value, list) else [value]
    if isinstance(value, list) and not isinstance(action, Listed):
        raise ValueError(f"{key} takes one value, got a list")
    if any(isinstance(v, (bool, dict, list)) for v in values):
        raise ValueError(f"{key} takes {'values' if isinstance(value, list) else 'a value'}, got {value!r}")
    return [f"{flag}={v}" for v in values]


def apply(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Set ``args``' options from its ``--config`` file where the command line did not give them (``parser``:
    growjax's); the parser's one-line error (exit 2) naming the file for a bad file, key or value."""
    parsers = subparsers(parser)
    command = parsers[args.command]
    command.source = Path(args.config)
    try:
        try:
            chosen = entries(read(command.source), args.command, parsers)
            own = keys(command)
            words = [w for key, value in chosen.items() for w in tokens(key, value, own[key])]
        except ValueError as err:
            command.error(str(err))
        from_file = command.parse_args(words)
    finally:
        command.source = None
    for dest in from_file.given - args.given:
        setattr(args, dest, getattr(from_file, dest))
    args.given |= from_file.given


__all__ = ["apply", "entries", "keys", "read", "tokens"]
