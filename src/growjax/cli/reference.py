"""The command-line reference page, generated from the parser: every command's options, common and rare, with
their meaning and default. ``python -m growjax.cli.reference > docs/cli.md`` writes the documentation's page."""

from __future__ import annotations

import argparse
import re

from growjax.cli import COMMANDS, build_parser, options

INTRO = """# Command-line reference

<!-- Generated from the parser by `python -m growjax.cli.reference > docs/cli.md`; edit the options, not this page. -->

Every command runs as `growjax COMMAND [DATA] [options]`. `growjax COMMAND --help` lists its common options,
`growjax COMMAND --help-all` its rare ones too; this page lists both, with their defaults.

- **One meaning.** An option means the same in every command that takes it (`--starts`, `--scout`, `--tolerance`,
  `--seed`, ...); only its default may differ.
- **Lists.** An option of several values takes them comma-separated in one argument and may be repeated:
  `--free Y,ext` is `--free Y --free ext`. No option takes several space-separated values, so none swallows a
  DATA file placed after it.
- **A configuration file.** `--config FILE.toml` reads options from a file, under the command line (an option
  given on the command line wins). Its top-level keys are long options without the dashes; a `[COMMAND]` table
  holds options for that command alone and wins over the top level, so one file can serve several commands (a
  top-level key that another command takes is left to it). A key no command takes is an error naming the key and
  the file.

```toml
seed = 1
free = ["Y", "ext"]        # a list option: a TOML list
rig-tangents = false       # a switch: true or false

[design]
for = "Y"
scout = 128
```
"""


def invocation(action: argparse.Action) -> str:
    """How ``action`` is written on the command line: its flags and the value's placeholder."""
    if not action.option_strings:
        return "DATA ..." if action.nargs == "*" else "DATA"
    flags = ", ".join(action.option_strings)
    if action.nargs == 0:
        return flags
    if action.metavar:
        value = action.metavar
    elif action.choices:
        value = "{" + ",".join(str(c) for c in action.choices) + "}"
    else:
        value = action.dest.upper()
    return f"{flags} {value}"


def meaning_and_default(parser: argparse.ArgumentParser, action: argparse.Action) -> tuple[str, str]:
    """(meaning, default) of ``action`` as its help line gives them; default '' for a switch."""
    text = " ".join(options.Formatter(parser.prog).help_text(action).split())
    found = re.fullmatch(r"(.*?)\s*\(default: (.*)\)", text, re.DOTALL)
    return (found.group(1), found.group(2)) if found else (text, "")


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("$", "\\$")


def _table(parser, actions) -> list[str]:
    rows = ["| option | meaning | default |", "|---|---|---|"]
    for action in actions:
        meaning, default = meaning_and_default(parser, action)
        rows.append(f"| `{invocation(action)}` | {_cell(meaning)} | {_cell(default) or '–'} |")
    return rows


def _key(parser, action) -> tuple[str, str]:
    """(invocation, meaning) of an option: what makes two commands' options the same one."""
    return invocation(action), meaning_and_default(parser, action)[0]


def shared_options(parsers: dict) -> dict:
    """{(invocation, meaning): [command, ...]} of the options two or more commands take alike."""
    taken: dict = {}
    for name, parser in parsers.items():
        for action in parser._actions:
            if action.dest != "help":
                taken.setdefault(_key(parser, action), []).append(name)
    return {key: names for key, names in taken.items() if len(names) > 1}


def _shared_table(shared: dict) -> list[str]:
    rows = ["| option | meaning | commands |", "|---|---|---|"]
    for (flag, meaning), names in shared.items():
        rows.append(f"| `{flag}` | {_cell(meaning)} | {', '.join(names)} |")
    return rows


def section(name: str, about: str, parser: argparse.ArgumentParser, shared: dict | None = None) -> list[str]:
    """The page's section of the command ``name``: its usage, its own options (common, then rare) and, for the
    options of ``shared`` (`shared_options`), their defaults in this command."""
    shared = shared or {}
    actions = [a for a in parser._actions if a.dest != "help"]
    own = [a for a in actions if _key(parser, a) not in shared]
    common = [a for a in own if not options.is_rare(a)]
    rare = [a for a in own if options.is_rare(a)]
    lines = [f"## growjax {name}", "", about[0].upper() + about[1:] + ".", "", f"`{parser.usage}`", ""]
    if common:
        lines += _table(parser, common)
    if rare:
        lines += ["", "Rare options (`--help-all`):", ""] + _table(parser, rare)
    also = [a for a in actions if _key(parser, a) in shared]
    if also:
        listed = ", ".join(
            f"`{invocation(a)}`"
            + (f" ({meaning_and_default(parser, a)[1]})" if meaning_and_default(parser, a)[1] else "")
            for a in also
        )
        lines += ["", f"Shared options, with their defaults here: {_cell(listed)}."]
    return lines + [""]


def page() -> str:
    """The whole page, Markdown."""
    parsers = options.subparsers(build_parser())
    parsers = {c.NAME: parsers[c.NAME] for c in COMMANDS}
    shared = shared_options(parsers)
    lines = [INTRO, "## Options several commands share", ""] + _shared_table(shared) + [""]
    for command in COMMANDS:
        lines += section(command.NAME, command.HELP, parsers[command.NAME], shared)
    return "\n".join(lines)


__all__ = ["INTRO", "invocation", "meaning_and_default", "page", "section", "shared_options"]


if __name__ == "__main__":
    print(page(), end="")
