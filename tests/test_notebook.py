"""The tutorials: each sets its sizes in its first code cell, as a reader runs them; `notebooks/sizes.toml` alone
reduces them for the documentation's test; each is stored executed, with its outputs, kept small; and each runs top
to bottom at full size (slow)."""

import ast
import importlib.util
import json
import re
import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = REPO / "notebooks"
TUTORIALS = sorted(NOTEBOOKS.glob("*.ipynb"))
# Tutorials not yet stored executed, each with the reason; the documentation's test does not execute them either.
NOT_STORED: dict[str, str] = {}
MAX_BYTES = 1_500_000  # a stored notebook, its figures included


def _execute():
    """notebooks/execute.py, the script that executes the tutorials and stores their outputs."""
    spec = importlib.util.spec_from_file_location("execute", NOTEBOOKS / "execute.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _cells(path: Path, kind: str = "code") -> list[dict]:
    return [c for c in json.loads(path.read_text())["cells"] if c["cell_type"] == kind]


def _visible(path: Path) -> list[str]:
    """The source of each code cell the site shows (those not tagged ``hide``)."""
    return ["".join(c["source"]) for c in _cells(path) if "hide" not in c["metadata"].get("tags", [])]


def _assigned(source: str) -> dict:
    """{name: value} of the literal values a cell assigns at its top level (``A = 1``, ``A, B = 1, 2``)."""
    values = {}
    for stmt in ast.parse(source).body:
        if not isinstance(stmt, ast.Assign) or len(stmt.targets) != 1:
            continue
        target = stmt.targets[0]
        names = [target] if isinstance(target, ast.Name) else getattr(target, "elts", [])
        try:
            value = ast.literal_eval(stmt.value)
        except ValueError:
            continue
        if isinstance(target, ast.Name):
            values[target.id] = value
        elif all(isinstance(n, ast.Name) for n in names) and len(names) == len(value):
            values.update({n.id: v for n, v in zip(names, value)})
    return values


def test_sizes_lists_every_tutorial_with_a_full_and_a_reduced_table():
    sizes = _execute().sizes()
    assert sorted(sizes) == sorted(p.stem for p in TUTORIALS)
    for name, entry in sizes.items():
        assert set(entry["full"]) == set(entry["ci"]), name
        assert entry["full"] == {} or entry["ci"] != entry["full"], f"{name}: the reduced sizes reduce nothing"


def test_sizes_refuses_tables_that_do_not_match(tmp_path):
    execute = _execute()
    (tmp_path / "sizes.toml").write_text("[a.full]\nN = 5\n[a.ci]\nM = 1\n")
    with pytest.raises(ValueError, match=r"\[a.full\] and \[a.ci\] set different names"):
        execute.sizes(tmp_path / "sizes.toml")
    (tmp_path / "sizes.toml").write_text("[a.full]\nN = 5\n")
    with pytest.raises(ValueError, match=r"needs a \[a.full\] and a \[a.ci\] table"):
        execute.sizes(tmp_path / "sizes.toml")


@pytest.mark.parametrize("path", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_the_first_code_cell_sets_the_full_sizes_and_the_figures_folder(path):
    """A reader who copies the visible code runs the full sizes: the first code cell sets each of them as
    sizes.toml's [NAME.full] does, and names the folder the figures go to; no visible cell reads the environment."""
    full = _execute().sizes()[path.stem]["full"]
    first, *rest = _visible(path)
    assert _cells(path)[0]["source"] and "hide" not in _cells(path)[0]["metadata"].get("tags", [])
    assigned = _assigned(first)
    assert {k: assigned.get(k) for k in full} == full
    assert f'FIGURES = Path("out/tutorials/{path.stem}")' in first
    for source in (first, *rest):
        assert "QUICK" not in source and "os.environ" not in source, source
    for source in rest:
        assert not set(_assigned(source)) & set(full), "a size set again below the first cell"


@pytest.mark.parametrize("path", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_figures_are_saved_under_the_folder_the_notebook_names(path):
    calls = [
        line
        for source in _visible(path)
        for line in source.splitlines()
        if re.search(r"\.savefig\(|_figure\(", line) and "import" not in line
    ]
    assert calls, "the notebook saves no figure"
    assert all("FIGURES /" in line for line in calls), calls


@pytest.mark.parametrize(
    "path",
    [
        pytest.param(p, marks=pytest.mark.xfail(strict=True, reason=NOT_STORED[p.stem])) if p.stem in NOT_STORED else p
        for p in TUTORIALS
    ],
    ids=[p.stem for p in TUTORIALS],
)
def test_stored_executed_with_small_outputs_and_honest_about_their_sizes(path):
    """Every code cell ran, in order, without an error; no timing metadata, no machine's paths, no giant file; the
    first markdown cell says so when the outputs were made at the reduced sizes, and names them."""
    execute = _execute()
    nb = json.loads(path.read_text())
    cells = _cells(path)
    assert [c["execution_count"] for c in cells] == list(range(1, len(cells) + 1)), "not executed top to bottom"
    assert not [o for c in cells for o in c["outputs"] if o["output_type"] == "error"]
    assert not [c for c in nb["cells"] if "execution" in c["metadata"]]
    assert any(o.get("data", {}).get("image/png") for c in cells for o in c["outputs"]), "no figure shown"
    text = path.read_text()
    assert path.stat().st_size < MAX_BYTES, path.stat().st_size
    assert str(REPO) not in text and "/tmp/" not in text
    sizes = nb["metadata"]["growjax"]["sizes"]
    entry = execute.sizes()[path.stem]
    first = "".join(_cells(path, "markdown")[0]["source"])
    if sizes == "ci" and entry["ci"] != entry["full"]:
        assert first.endswith(execute.notice(entry)), "the notice does not name sizes.toml's reduced sizes"
    else:
        assert sizes == "full" and execute.NOTICE not in first


def test_the_reduced_sizes_notice_is_added_replaced_and_removed():
    execute = _execute()
    entry = {"full": {"N": 500, "T_END": 10.0, "K": 3}, "ci": {"N": 24, "T_END": 3.0, "K": 3}}
    text = execute.notice(entry)
    assert "`N = 24` (as written: `500`)" in text and "`T_END = 3.0` (as written: `10.0`)" in text
    assert "K =" not in text  # a size the same in both is not reduced
    page = "# Title\n\nWhat it does."
    shown = execute.with_notice(page, text)
    assert shown == page + "\n\n" + text
    assert execute.with_notice(execute.with_notice(shown, "> **Outputs shown at reduced sizes** x"), None) == page


@pytest.mark.slow  # minutes each: 0–10 s of data, full NUTS runs, the reference configuration
@pytest.mark.parametrize("path", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_tutorial_executes_at_full_size(path, tmp_path):
    pytest.importorskip("nbclient")
    shutil.copy(NOTEBOOKS / "sizes.toml", tmp_path)
    shutil.copy(path, tmp_path)
    _execute().execute(tmp_path / path.name, ci=False)  # hidden checks included
    assert any((tmp_path / "out" / "tutorials" / path.stem).glob("*.png"))
