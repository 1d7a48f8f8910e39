"""The documentation site builds with ``mkdocs build --strict``, executing every tutorial in quick mode; its
tutorials are the notebooks in the top-level ``notebooks/`` folder, kept there alone."""

import os
import re
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
    assert sorted(nav) == sorted(p.name for p in NOTEBOOKS.glob("*.ipynb")) and len(nav) == 8


@pytest.mark.docs
def test_docs_build_strict_with_executed_tutorials(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocs_jupyter")
    pytest.importorskip("mkdocstrings_handlers.python")
    env = dict(os.environ, GROWJAX_QUICK="1", GROWJAX_DOCS_CACHE="false", NO_MKDOCS_2_WARNING="1")
    start = time.perf_counter()
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
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
        "tutorials/simulate",
        "tutorials/sweep",
        "tutorials/fit_posterior",
        "tutorials/discover",
        "tutorials/control",
        "tutorials/sets",
        "tutorials/design",
        "tutorials/track",
    ):
        assert (site / page / "index.html").is_file(), page
    assert sorted(p.name for p in (site / "tutorials").rglob("*") if p.is_file() and p.suffix != ".html") == sorted(
        p.name for p in NOTEBOOKS.glob("*.ipynb")
    )  # the notebooks, not what running them may leave beside them
    simulate = (site / "tutorials" / "simulate" / "index.html").read_text()
    assert "length RMSE against the data" in simulate and "data:image/png" in simulate  # executed, with figures
    print(f"mkdocs build --strict: {wall:.1f} s")
