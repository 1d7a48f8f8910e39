"""The documentation site builds with ``mkdocs build --strict`` from the tutorials' stored outputs, after every
tutorial has been executed at its reduced sizes; its tutorials are the notebooks in the top-level ``notebooks/``
folder, kept there alone."""

import importlib.util
import os
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = REPO / "notebooks"


def test_the_sites_tutorials_are_the_notebooks_folder():
    """docs/tutorials is a relative link to notebooks/ (no second copy), and the site's navigation lists every
    notebook there and nothing else."""
    link = REPO / "docs" / "tutorials"
    assert link.is_symlink() and str(link.readlink()) == "../notebooks", link
    assert link.resolve() == NOTEBOOKS.resolve()
    assert not any(p.suffix == ".ipynb" for p in (REPO / "docs").rglob("*") if not p.is_relative_to(link))
    nav = re.findall(r"tutorials/(\w+\.ipynb)", (REPO / "mkdocs.yml").read_text())
    assert sorted(nav) == sorted(p.name for p in NOTEBOOKS.glob("*.ipynb")) and len(nav) >= 7
    assert sorted(nav) == sorted(f"{name}.ipynb" for name in _execute().sizes())  # each has its sizes


def _execute():
    """notebooks/execute.py, the script that executes the tutorials and stores their outputs."""
    spec = importlib.util.spec_from_file_location("execute", NOTEBOOKS / "execute.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# Tutorials whose reduced-size run is still long: executed with ``-m "docs and slow"`` (their stored outputs are
# still checked by tests/test_notebook.py, and their workflow by its own tests).
SLOW_TUTORIALS = {
    "design": "at its reduced sizes it needs about 700 s of CPU on an empty compilation cache, mostly compiling "
    "its searches (tests/test_design.py runs the workflow)",
}


def _tutorials() -> list:
    """Each tutorial sizes.toml lists, as a parameter; those not yet stored executed are skipped with the reason,
    the long ones marked slow."""
    from test_notebook import NOT_STORED

    params = []
    for name in _execute().sizes():
        if name in NOT_STORED:
            params.append(pytest.param(name, marks=pytest.mark.skip(reason=NOT_STORED[name])))
        elif name in SLOW_TUTORIALS:
            params.append(pytest.param(name, marks=pytest.mark.slow))
        else:
            params.append(name)
    return params


@pytest.mark.docs
@pytest.mark.parametrize("name", _tutorials())
def test_tutorial_executes_at_reduced_sizes(name, tmp_path):
    """The tutorial runs top to bottom at its reduced sizes, hidden checks included, in a kernel of its own
    started in a folder of its own (a copy; the stored one is not touched), and saves its figures where it says."""
    pytest.importorskip("nbclient")
    execute = _execute()
    shutil.copy(NOTEBOOKS / "sizes.toml", tmp_path)
    shutil.copy(NOTEBOOKS / f"{name}.ipynb", tmp_path)
    start, cpu = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    execute.execute(tmp_path / f"{name}.ipynb", ci=True, timeout=900)  # a cell that raises fails the test
    assert any((tmp_path / "out" / "tutorials" / name).glob("*.png")), f"{name} saved no figure where it says"
    used = resource.getrusage(resource.RUSAGE_CHILDREN)  # the kernel's, once it has exited
    seconds = used.ru_utime + used.ru_stime - cpu.ru_utime - cpu.ru_stime
    print(f"{name} at its reduced sizes: {time.perf_counter() - start:.0f} s, the kernel's CPU {seconds:.0f} s")


@pytest.mark.docs
def test_docs_build_strict(tmp_path):
    """The site builds strictly from the tutorials' stored outputs, every page and every public name rendered."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocs_jupyter")
    pytest.importorskip("mkdocstrings_handlers.python")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    start = time.perf_counter()
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    wall = time.perf_counter() - start
    assert run.returncode == 0, run.stderr[-6000:]
    site = tmp_path / "site"
    for page in (
        "getting-started",
        "model",
        "data",
        "results",
        "uncertainty",
        "design",
        "tracking",
        "benchmarks",
        "api",
        *(f"tutorials/{p.stem}" for p in NOTEBOOKS.glob("*.ipynb")),
    ):
        assert (site / page / "index.html").is_file(), page
    assert sorted(p.name for p in (site / "tutorials").rglob("*") if p.is_file() and p.suffix != ".html") == sorted(
        p.name for p in NOTEBOOKS.glob("*.ipynb")
    )  # the notebooks, not what running them may leave beside them
    api = {
        i
        for page in ("api", "api-tracking")
        for i in re.findall(r'id="([^"]+)"', (site / page / "index.html").read_text())
    }
    unrendered = [name for name in _rendered_api_names() if name not in api]
    assert not unrendered, f"docs/api.md does not render {unrendered}"
    simulate = (site / "tutorials" / "simulate" / "index.html").read_text()
    assert "length RMSE against the data" in simulate and "data:image/png" in simulate  # stored outputs, figures
    print(f"mkdocs build --strict: {wall:.1f} s")


# -- the pages themselves: short, current, complete ---------------------------------------------------------------

DOCS = REPO / "docs"
GENERATED = {"benchmarks.md", "cli.md"}  # written by benchmarks/report.py and the command line's reference script
REFERENCE = {"cli.md"}  # the command line's every option: long by nature
MAX_LINES = 250
MAX_WORDS = 10_000
# Development history in prose: phrases that cannot be ordinary description of what the package does.
HISTORY = re.compile(
    r"\b(previously|no longer|formerly|earlier versions?|in the past|used to be"
    r"|(?:was|were|has been|have been) (?:fixed|renamed|removed|replaced|changed)"
    r"|(?:is|are) now\b|now (?:uses|takes|gives|returns|reads|writes|defaults)"
    r"|(?:before|after) (?:the|this) (?:fix|change|release|rewrite))\b",
    re.IGNORECASE,
)
# A version of growjax named in prose ("growjax 0.5.0", "version 0.3", "since 0.7.1"): only the current one may be.
VERSION = re.compile(
    r"\b(?:growjax|version)\s+v?(\d+\.\d+(?:\.\d+)?)\b|\b(?:in|since|until|from|before|after)\s+v?(\d+\.\d+\.\d+)\b",
    re.IGNORECASE,
)


def _pages():
    return sorted(p for p in DOCS.glob("*.md") if p.name != "changelog.md")


def _nav() -> list[tuple[str, str]]:
    """(title, target) of every entry of mkdocs.yml's nav, sections excluded."""
    text = (REPO / "mkdocs.yml").read_text()
    nav = text[text.index("\nnav:") : text.index("\n\n", text.index("\nnav:"))]
    return re.findall(r"^\s*-\s*([^:\n]+):\s*(\S+\.(?:md|ipynb))\s*$", nav, flags=re.MULTILINE)


def _docstrings():
    """(where, text) of every docstring of the package: modules, classes, functions and attributes."""
    import ast

    for path in sorted((REPO / "src" / "growjax").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            body = getattr(node, "body", None)
            if not isinstance(body, list):
                continue
            for stmt in body:
                if (
                    isinstance(stmt, ast.Expr)
                    and isinstance(stmt.value, ast.Constant)
                    and isinstance(stmt.value.value, str)
                ):
                    yield f"{path.relative_to(REPO)}:{stmt.lineno}", stmt.value.value


def test_every_page_is_short():
    long = {
        p.name: n for p in _pages() if p.name not in REFERENCE and (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert not long, f"pages over {MAX_LINES} lines: {long}"


def test_the_docs_are_under_the_word_budget():
    words = {p.name: len(p.read_text().split()) for p in _pages() if p.name not in GENERATED}
    assert sum(words.values()) < MAX_WORDS, f"{sum(words.values())} words: {words}"


def test_no_history_in_docs_readme_or_docstrings():
    from growjax import __version__

    texts = [(p.relative_to(REPO), p.read_text()) for p in _pages()]
    texts += [("README.md", (REPO / "README.md").read_text()), *_docstrings()]
    hits = [f"{where}: {m.group(0)!r}" for where, text in texts for m in HISTORY.finditer(text)]
    for where, text in texts:
        if str(where) == "docs/results.md":
            continue  # its one environment line names the version its figures were made with
        hits += [
            f"{where}: {m.group(0)!r}" for m in VERSION.finditer(text) if (m.group(1) or m.group(2)) != __version__
        ]
    assert not hits, "history wording (it belongs in CHANGELOG.md):\n" + "\n".join(hits)


def test_the_history_patterns_fire_on_history_and_not_on_description():
    assert HISTORY.search("The fit previously used secants") and HISTORY.search("this bug was fixed")
    assert HISTORY.search("the option is now called --sets") and HISTORY.search("it no longer refuses")
    for prose in ("the chunk in flight finishes before the run stops", "the pressure now and then", "used to fit Y"):
        assert not HISTORY.search(prose), prose
    assert VERSION.search("growjax 0.5.0").group(1) == "0.5.0" and VERSION.search("since 0.7.1").group(2) == "0.7.1"
    assert not VERSION.search("jax 0.10.2") and not VERSION.search("from 0.001 s to 10 s")


def test_the_navigation_lists_every_page_once_under_unique_titles():
    nav = _nav()
    titles = [t.strip() for t, _ in nav]
    assert len(titles) == len(set(titles)), [t for t in titles if titles.count(t) > 1]
    targets = [t for _, t in nav]
    assert len(targets) == len(set(targets))
    assert {p.name for p in DOCS.glob("*.md")} <= set(targets), "a page outside the navigation"


def test_the_changelog_page_includes_the_changelog():
    text = (DOCS / "changelog.md").read_text()
    assert re.search(r'--8<--\s+"CHANGELOG\.md"', text) and len(text.splitlines()) < 5  # included, not copied
    assert "pymdownx.snippets" in (REPO / "mkdocs.yml").read_text()


# -- the API page: every public name of every public module ---------------------------------------------------


def _public_modules():
    import importlib
    import pkgutil

    import growjax

    names = ["growjax"] + [
        m.name
        for m in pkgutil.walk_packages(growjax.__path__, "growjax.")
        if not any(part.startswith("_") for part in m.name.split(".")[1:])
    ]
    return {name: importlib.import_module(name) for name in sorted(names)}


def _api_blocks() -> dict[str, list[str] | None]:
    """{identifier: the members it lists, or None for all of its public names} of docs/api.md's ``:::`` blocks."""
    text = "".join(p.read_text() for p in sorted(DOCS.glob("api*.md")))
    blocks = {}
    for m in re.finditer(r"^::: (\S+)\n((?:    .*\n)*)", text, flags=re.MULTILINE):
        listed = re.search(r"members:\s*\[([^\]]*)\]", m.group(2))
        blocks[m.group(1)] = None if listed is None else [n.strip() for n in listed.group(1).split(",") if n.strip()]
    return blocks


def test_api_page_documents_every_public_name():
    """Each name in a public module's ``__all__`` is rendered by some block of the page: that module's, or one
    re-exporting the same object under the same name; every block names a module and members that exist."""
    import importlib

    modules = _public_modules()
    shown: dict[str, set[int]] = {}
    for ident, members in _api_blocks().items():
        module = importlib.import_module(ident)  # a block of a module that does not exist fails the build
        exported = getattr(module, "__all__", None)
        listed = members if members is not None else (exported or [])  # no __all__: nothing to account for
        for name in listed:
            assert hasattr(module, name), f"docs/api.md: {ident} has no {name}"
            assert exported is None or name in exported, f"docs/api.md: {name} is not in {ident}.__all__"
            shown.setdefault(name, set()).add(id(getattr(module, name)))
    missing = [
        f"{mod}.{name}"
        for mod, module in modules.items()
        for name in getattr(module, "__all__", ())
        if id(getattr(module, name)) not in shown.get(name, set())
    ]
    assert not missing, "public names missing from docs/api.md:\n" + "\n".join(missing)


def _rendered_api_names():
    """(anchor, identifier) of every name docs/api.md's blocks render: a block's listed members, or its module's
    ``__all__`` less the modules it re-exports (each has its own block)."""
    import importlib
    import types

    for ident, members in _api_blocks().items():
        module = importlib.import_module(ident)
        names = members if members is not None else getattr(module, "__all__", [])
        for name in names:
            if not isinstance(getattr(module, name), types.ModuleType):
                yield f"{ident}.{name}"


# -- the manifest the data page shows is one growjax reads ------------------------------------------------------


def test_the_data_pages_manifest_reads_as_documented(tmp_path):
    from growjax.data import sets

    text = (DOCS / "data.md").read_text()
    manifest = re.search(r"```toml\n(.*?)```", text, flags=re.DOTALL).group(1)
    for key in (
        "[defaults]",
        "[[experiment]]",
        "file",
        "name",
        "drive",
        "robot",
        "rig",
        "window",
        "sensors",
        "parameters",
    ):
        assert key in manifest, key
    shipped = REPO / "src" / "growjax" / "data" / "datasets" / "set" / "pulse_published.csv"
    for name in re.findall(r'file = "([^"]+)"', manifest):
        (tmp_path / name).write_text(shipped.read_text())
    (tmp_path / "set.toml").write_text(manifest)
    group = sets.read([tmp_path / "set.toml"])
    first, second = group.runs
    assert (first.name, first.robot, first.rig, first.drive) == ("pulse-a", "membrane-1", "bench", "forward")
    assert first.window == (0.0, 10.0) and first.sensors == ("length", "pressure")
    assert first.parameters == {"tank.length": 0.1, "robot.catheter_friction": 0.02}
    assert (second.name, second.drive, second.robot, second.sensors) == (
        "stepper_b",
        "inverse",
        "membrane-2",
        ("length",),
    )
    assert second.parameters == {"tank.length": 0.1, "f": 5.0}
