"""A regular (not editable) install into a fresh environment runs ``growjax simulate`` from another folder.

Fast and offline: the new environment sees this interpreter's packages through a ``.pth`` line (so no
dependency is downloaded), and only growjax itself is built and installed (``--no-deps --no-build-isolation``).
"""

import json
import os
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_regular_install_runs_simulate_elsewhere(tmp_path):
    pytest.importorskip("setuptools", minversion="77")  # an SPDX licence string in pyproject.toml
    pytest.importorskip("wheel")  # the build backend's bdist_wheel, without build isolation (the test extra has it)
    env_dir = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True)
    python = env_dir / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    # This interpreter's site folders as plain path lines: their .pth files (an editable growjax) stay inactive.
    parents = [p for p in {*site.getsitepackages(), sysconfig.get_path("purelib")} if Path(p).is_dir()]
    Path(purelib, "_parent_site.pth").write_text("\n".join(parents) + "\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    build = subprocess.run(
        [str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index", str(REPO)],
        env=env,
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=False,
    )
    if build.returncode != 0 and "No module named pip" in build.stderr:
        pytest.skip("pip is not importable from this interpreter's site folders")
    assert build.returncode == 0, build.stderr[-3000:]

    where = tmp_path / "elsewhere"
    where.mkdir()
    found = subprocess.run(
        [str(python), "-c", "import growjax, sys; print(growjax.__file__); print(growjax.__version__)"],
        env=env,
        capture_output=True,
        text=True,
        cwd=where,
        check=True,
    ).stdout.split()
    assert Path(found[0]).is_relative_to(env_dir), found  # the installed copy, not the source tree
    installed_data = Path(found[0]).parent / "data" / "datasets" / "synthetic_forward.csv"
    assert installed_data.is_file() and not installed_data.is_symlink()

    run = subprocess.run(
        [str(env_dir / "bin" / "growjax"), "simulate", "--json", "-"],
        env=env,
        capture_output=True,
        text=True,
        cwd=where,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout)
    assert summary["status"] == "ok" and Path(summary["data"]).is_relative_to(env_dir)  # the installed data
    assert summary["rmse_length_m"] < 4e-4  # simulated with the Y recorded beside the shipped data
    assert (where / "out" / "simulate" / "trajectory.csv").is_file()


def test_the_citation_names_the_packages_version():
    import growjax

    line = next(x for x in (REPO / "CITATION.cff").read_text().splitlines() if x.startswith("version:"))
    assert line.split(":", 1)[1].strip() == growjax.__version__
