"""One command-line vocabulary: a flag means the same in every command, list options take comma-separated values
and never swallow DATA, help shows real defaults, rare options hide behind --help-all, ``--config FILE.toml``
applies under the command line, and the reference page (docs/cli.md) is the parser's. Parse only: nothing runs."""

import json
import re
from pathlib import Path

import pytest

from growjax import cli
from growjax.cli import options, reference

REPO = Path(__file__).resolve().parents[1]
DEFAULT = re.compile(r"\s*\(default: .*\)$", re.DOTALL)


def _parsers() -> dict:
    return options.subparsers(cli.build_parser())


def _options(parser) -> list:
    """The options of a command's parser (its help option aside)."""
    return [a for a in parser._actions if a.option_strings and a.dest != "help"]


def _help(parser, action) -> str:
    return " ".join(options.Formatter(parser.prog).help_text(action).split())


def _parse(argv):
    return cli.build_parser().parse_args(argv)


def test_an_option_means_the_same_in_every_command_that_takes_it():
    """For every long option of two or more commands, its help (the default aside) and its values are the same."""
    seen: dict[str, dict] = {}
    for name, parser in _parsers().items():
        for action in _options(parser):
            text = DEFAULT.sub("", _help(parser, action))
            shape = (text, reference.invocation(action), action.nargs)
            for flag in action.option_strings:
                seen.setdefault(flag, {})[name] = shape
    shared = {flag: by for flag, by in seen.items() if len(by) > 1}
    assert {"--tolerance", "--starts", "--scout", "--seed", "--drive", "--json", "--law"} <= set(shared)
    clashes = {flag: by for flag, by in shared.items() if len(set(by.values())) > 1}
    assert not clashes, json.dumps(clashes, indent=1, ensure_ascii=False)


def test_the_renamed_counts_are_named_by_what_they_count():
    parsers = _parsers()
    flags = {name: {s for a in _options(p) for s in a.option_strings} for name, p in parsers.items()}
    assert {"--sets", "--sobol-points"} <= flags["sweep"] and not {"--n", "--sobol-n"} & flags["sweep"]
    assert {"--evaluate-on", "--tuning-draws", "--robust-rig"} <= flags["control"]
    assert not {"--fidelity", "--rtol", "--draws"} & flags["control"]
    renamed = {"--scout", "--descent-steps", "--check-draws", "--criterion-points"}
    assert renamed <= flags["design"] and not {"--random", "--iterations", "--draws", "--points"} & flags["design"]
    assert not {"--fidelity", "--rtol"} & flags["design"] and "--seed" not in flags["simulate"]
    assert {"--scout", "--starts"} <= flags["fit"]
    for name in parsers:
        assert {"--config", "--help-all"} <= {s for a in parsers[name]._actions for s in a.option_strings}, name


def test_help_shows_real_defaults():
    """No "(default: None)" or "(default: [])"; an option with a value states its default, in its help line."""
    for name, parser in _parsers().items():
        for rare in (False, True):
            text = " ".join(parser.format_help(rare=rare).split())
            assert "(default: None)" not in text and "(default: [])" not in text, name
            assert "(default: False)" not in text and "(default: True)" not in text, name
        for action in _options(parser):
            line = _help(parser, action)
            assert line.count("(default:") <= 1 and ("(default:" not in line or DEFAULT.search(line)), (name, line)
            if action.nargs != 0:
                assert DEFAULT.search(line), (name, action.option_strings, line)
    knots = [a for a in _parsers()["design"]._actions if "--knot-spacing" in a.option_strings][0]
    assert _help(_parsers()["design"], knots).endswith("(default: 0.5)")


def test_design_help_shows_at_most_15_options_and_help_all_every_one(capsys):
    parser = _parsers()["design"]
    shown = re.findall(r"^  (-[-\w]+)", parser.format_help(), re.MULTILINE)
    assert "-h" in shown and len([f for f in shown if f != "-h"]) <= 15, shown
    assert "--descent-steps" not in shown and "--for" in shown and "--config" in shown
    with pytest.raises(SystemExit) as stop:
        cli.main(["design", "--help-all"])
    everything = capsys.readouterr().out
    assert stop.value.code == 0 and options.RARE_TITLE in everything
    for action in _options(parser):
        assert action.option_strings[0] in everything, action.option_strings


@pytest.mark.parametrize(
    "argv, dest, value, data",
    [
        (["fit", "--free", "Y,ext", "data.csv"], "free", ["Y", "ext"], ["data.csv"]),
        (
            ["fit", "--free", "Y", "--free", "ext@robot", "a.csv", "b.csv"],
            "free",
            ["Y", "ext@robot"],
            ["a.csv", "b.csv"],
        ),
        (
            ["discover", "--candidates", "fluid_leak,actuation_lag", "x.csv"],
            "candidates",
            ["fluid_leak", "actuation_lag"],
            ["x.csv"],
        ),
        (["design", "--for", "Y,ext", "x.csv"], "design_for", ["Y", "ext"], "x.csv"),
        (
            ["design", "--discriminate", "retraction_folding,trapped_air", "x.csv"],
            "discriminate",
            ["retraction_folding", "trapped_air"],
            "x.csv",
        ),
        (["design", "--size", "0.2,3e-3", "x.csv"], "size", [0.2, 3e-3], "x.csv"),
        (["design", "--sensors", "length,pressure", "x.csv"], "sensors", ["length", "pressure"], "x.csv"),
        (
            ["sweep", "--range", "Y=5000:15000,ext=4000:10000:log", "x.csv"],
            "range",
            ["Y=5000:15000", "ext=4000:10000:log"],
            "x.csv",
        ),
        (["simulate", "--param", "Y=8000,ext=5e-6", "x.csv"], "param", ["Y=8000", "ext=5e-6"], "x.csv"),
        (
            ["fit", "--tolerance", "Kp=0.1", "--tolerance", "mu_c=0.3", "x.csv"],
            "tolerance",
            ["Kp=0.1", "mu_c=0.3"],
            ["x.csv"],
        ),
    ],
)
def test_a_list_option_takes_commas_and_repeats_and_never_swallows_data(argv, dest, value, data):
    args = _parse(argv)
    assert getattr(args, dest) == value and args.data == data


def test_a_list_option_replaces_its_default_and_refuses_an_empty_item(capsys):
    assert _parse(["design"]).sensors == ["length"]
    assert _parse(["design", "--sensors", "length", "--sensors", "pressure"]).sensors == ["length", "pressure"]
    assert _parse(["fit"]).free == [] and _parse(["discover"]).candidates is None
    for argv, named in (
        (["fit", "--free", "Y,,ext"], "--free: 'Y,,ext' has an empty item"),
        (["discover", "--candidates", "fluid_leak,bogus"], "unknown effect 'bogus'"),
        (["design", "--sensors", "length,flow"], "invalid choice 'flow'"),
        (["posterior", "--rig", "fixed"], "growjax posterior takes inferred only"),
        (["discover", "--rig-errors", "experiment"], "growjax discover takes shared only"),
    ):
        with pytest.raises(SystemExit) as stop:
            _parse(argv)
        err = capsys.readouterr().err.strip()
        assert stop.value.code == 2 and len(err.splitlines()) == 1 and named in err, err


def _config(tmp_path, text: str) -> str:
    path = tmp_path / "options.toml"
    path.write_text(text)
    return str(path)


def test_config_keys_apply_under_the_command_line(tmp_path):
    path = _config(
        tmp_path,
        'seed = 7\nfree = ["Y", "ext"]\nrig-tangents = false\nquiet = true\nsets = 50\n'
        '[design]\nfor = "Y,ext"\nscout = 12\n[sweep]\nchunk-size = 100\n',
    )
    fit = _parse(["fit", "x.csv", "--config", path])
    assert (fit.seed, fit.free, fit.rig_tangents, fit.quiet) == (7, ["Y", "ext"], False, True)
    assert {"seed", "free", "rig_tangents", "quiet"} <= fit.given and fit.data == ["x.csv"]
    fit = _parse(["fit", "--config", path, "--seed", "3", "--free", "n", "--rig-tangents"])
    assert (fit.seed, fit.free, fit.rig_tangents) == (3, ["n"], True)  # the command line wins, lists whole
    design = _parse(["design", "--config", path])
    assert (design.design_for, design.scout, design.seed) == (["Y", "ext"], 12, 7)
    sweep = _parse(["sweep", "--config", path, "--sets", "20"])
    assert (sweep.chunk_size, sweep.sets, sweep.seed) == (100, 20, 7)
    simulate = _parse(["simulate", "--config", path])  # seed, free, sets: other commands' keys, left to them
    assert not hasattr(simulate, "seed") and simulate.quiet


@pytest.mark.parametrize(
    "text, named",
    [
        ("bogus = 1\n", "unknown key 'bogus'"),
        ("[fit]\nsets = 10\n", "unknown key 'sets' in [fit]"),
        ("[nothing]\nseed = 1\n", "unknown table [nothing]"),
        ("seed = -1\n", "--seed: must be at least 0"),
        ("seed = [1, 2]\n", "seed takes one value"),
        ("quiet = 1\n", "quiet is a switch"),
        ("config = 'other.toml'\n", "key 'config': --config is for the command line only"),
        ("seed = \n", "not valid TOML"),
    ],
)
def test_config_refuses_a_bad_key_or_value_with_one_line_naming_it_and_the_file(tmp_path, capsys, text, named):
    path = _config(tmp_path, text)
    with pytest.raises(SystemExit) as stop:
        _parse(["fit", "--config", path])
    err = capsys.readouterr().err.strip()
    assert stop.value.code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"growjax fit: error: {path}: ") and named in err, err


def test_the_reference_page_is_the_parsers():
    page = (REPO / "docs" / "cli.md").read_text()
    assert page == reference.page(), "docs/cli.md is stale: python -m growjax.cli.reference > docs/cli.md"
    sections = dict(re.findall(r"^## growjax (\w+)\n(.*?)(?=^## |\Z)", page, re.MULTILINE | re.DOTALL))
    assert list(sections) == [c.NAME for c in cli.COMMANDS]
    for name, parser in _parsers().items():
        for action in _options(parser):
            for flag in action.option_strings:
                assert f"`{flag}" in sections[name] or f", {flag}" in sections[name], (name, flag)
    assert "Command-line reference: cli.md" in (REPO / "mkdocs.yml").read_text()


def _documented() -> list[tuple[str, str, str]]:
    """(where, command, --flag) of every option named on a `growjax COMMAND ...` line of the README, the docs'
    pages and the notebooks' cells (a line's continuations joined; an inline span ends at its backtick)."""
    texts = [(p, p.read_text()) for p in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]]
    for notebook in sorted((REPO / "notebooks").glob("*.ipynb")):
        cells = json.loads(notebook.read_text())["cells"]
        texts += [(notebook, "".join(c["source"])) for c in cells]
    commands = "|".join(c.NAME for c in cli.COMMANDS)
    found = []
    for path, text in texts:
        text = re.sub(r"\\\n\s*", " ", text)
        for m in re.finditer(rf"growjax ({commands})\b([^`\n#]*)", text):
            found += [(path.name, m.group(1), flag) for flag in re.findall(r"(?<![\w-])--[a-z][\w-]*", m.group(2))]
    return found


def test_every_option_the_documentation_names_exists():
    documented = _documented()
    assert len(documented) > 40 and ("README.md", "sweep", "--sets") in documented
    flags = {name: {s for a in p._actions for s in a.option_strings} for name, p in _parsers().items()}
    missing = sorted({d for d in documented if d[2] not in flags[d[1]]})
    assert not missing, missing
