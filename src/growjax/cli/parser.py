"""growjax's argument parser: one-line errors, real defaults in help, the rare options hidden from ``--help`` and
shown by ``--help-all``, ``--config FILE.toml`` applied under the command line, comma-separated list options, and
which options the command line spelled out."""

from __future__ import annotations

import argparse
import sys

from growjax.cli.command import BAD_INPUT

RARE_TITLE = "rare options (hidden from --help)"


class Formatter(argparse.HelpFormatter):
    """Help with each option's real default: a value, a comma-separated list, or the help's own
    ``(default: ...)``; nothing for a switch or an option whose help states what its absence means."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if "(default:" in text or action.nargs == 0 or default is None or default is argparse.SUPPRESS:
            return text
        if not action.option_strings and action.nargs not in ("?", "*"):
            return text
        if isinstance(default, (list, tuple)):
            if not default:
                return text
            default = ",".join(str(d) for d in default)
        return f"{text} (default: {str(default).replace('%', '%%')})"

    def help_text(self, action: argparse.Action) -> str:
        """The help line of ``action`` as ``--help`` prints it (its default included), unwrapped."""
        return self._expand_help(action) if action.help else ""


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block) naming the problem and the valid values, a help option
    ``-h, --help, --help-all`` (``--help-all``: the rare options too), ``--config FILE.toml`` applied under the
    command line, and the parsed arguments' ``given``: the options the command line (or the file) spelled out, a
    value equal to the default included."""

    def __init__(self, *args, **kwargs):
        add_help = kwargs.pop("add_help", True)
        kwargs.setdefault("formatter_class", Formatter)
        super().__init__(*args, add_help=False, **kwargs)
        self.source = None  # the config file being read, named in errors
        if add_help:
            self.add_argument(
                "-h",
                "--help",
                "--help-all",
                action=_Help,
                help="show the common options and exit (--help-all: every option, the rare ones too)",
            )

    def error(self, message):
        where = f"{self.source}: " if self.source else ""
        self.exit(BAD_INPUT, f"{self.prog}: error: {where}{message}\n")

    def parse_args(self, args=None, namespace=None):
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:  # named by the command's own parser: "growjax control: error: unrecognized arguments: …"
            self._parser_of(parsed).error(f"unrecognized arguments: {' '.join(extras)}")
        if namespace is None:
            parsed.given = _given(self, args)
            if getattr(parsed, "config", None):
                from growjax.cli import config

                config.apply(self, parsed)
        return parsed

    def _parser_of(self, parsed) -> argparse.ArgumentParser:
        """The subcommand's parser of ``parsed`` (this parser where there is none)."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                return action.choices.get(getattr(parsed, action.dest or "command", None), self)
        return self

    def format_help(self, rare: bool = False) -> str:
        """The help: the common options, and with ``rare`` the rare ones in a section of their own."""
        formatter = self._get_formatter()
        formatter.add_usage(self.usage, self._actions, self._mutually_exclusive_groups)
        formatter.add_text(self.description)
        for group in self._action_groups:
            formatter.start_section(group.title)
            formatter.add_text(group.description)
            formatter.add_arguments([a for a in group._group_actions if not is_rare(a)])
            formatter.end_section()
        if rare and any(is_rare(a) for a in self._actions):
            formatter.start_section(RARE_TITLE)
            formatter.add_arguments([a for a in self._actions if is_rare(a)])
            formatter.end_section()
        formatter.add_text(self.epilog)
        return formatter.format_help()


class _Help(argparse.Action):
    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        sys.stdout.write(parser.format_help(rare=option_string == "--help-all"))
        parser.exit()


class Listed(argparse.Action):
    """A list option: each use adds its comma-separated values (the type splits them); the first use replaces the
    default."""

    def __call__(self, parser, namespace, values, option_string=None):
        current = getattr(namespace, self.dest, None)
        start = [] if current is None or current is self.default else list(current)
        setattr(namespace, self.dest, start + list(values))


def is_rare(action: argparse.Action) -> bool:
    """Whether ``action`` is a rare option: hidden from ``--help``, shown by ``--help-all``."""
    return getattr(action, "rare", False)


def _given(parser: argparse.ArgumentParser, args) -> set:
    """Destinations set on the command line ``args``: the parse again with every default suppressed."""
    actions = [a for p in subparsers(parser).values() for a in p._actions] + parser._actions
    saved = [a.default for a in actions]
    try:
        for a in actions:
            a.default = argparse.SUPPRESS
        return set(vars(argparse.ArgumentParser.parse_args(parser, args, argparse.Namespace())))
    finally:
        for a, d in zip(actions, saved):
            a.default = d


def subparsers(parser: argparse.ArgumentParser) -> dict:
    """{command name: its parser} of ``parser``'s sub-commands ({} for none)."""
    found = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            found.update(action.choices)
    return found


__all__ = ["RARE_TITLE", "Formatter", "Listed", "Parser", "is_rare", "subparsers"]
