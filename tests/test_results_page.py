"""The generated pages: docs/results.md is what calibration/results_page.py renders from the committed results
files, of one version of growjax; docs/benchmarks.md is what benchmarks/report.py renders from benchmarks/results/,
one table per topic, a topic whose results file is absent or of another version marked not measured."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def page():
    return _module(REPO / "calibration" / "results_page.py")


@pytest.fixture(scope="module")
def report():
    return _module(REPO / "benchmarks" / "report.py")


def test_results_page_is_rendered_from_the_committed_files(page):
    assert (REPO / "docs" / "results.md").read_text() == page.render(), (
        "docs/results.md differs from its results files: run python calibration/results_page.py"
    )


def test_calibration_figures_reach_the_page(page, tmp_path):
    """A changed figure in a results file changes the page: the numbers are read, not written in."""
    results = tmp_path / "results"
    results.mkdir()
    for f in (REPO / "calibration" / "results").glob("*.json"):
        (results / f.name).write_text(f.read_text())
    record = json.loads((results / "calibration.json").read_text())
    record["fit"]["interval_90_Pa"] = [1234.0, 5678.0]
    record["fit_over_posterior_width_Y"] = 9.87
    (results / "calibration.json").write_text(json.dumps(record))
    text = page.render(results)
    assert "1234–5678 Pa" in text and "9.87" in text
    assert text != page.render()


def test_each_section_names_the_version_its_file_was_made_with(page, tmp_path):
    """Results files of different versions are each labelled: a section's figures say which growjax made them."""
    results = tmp_path / "results"
    results.mkdir()
    for f in (REPO / "calibration" / "results").glob("*.json"):
        (results / f.name).write_text(f.read_text())
    record = json.loads((results / "paper.json").read_text())
    record["environment"]["growjax"] = "0.0.1"
    (results / "paper.json").write_text(json.dumps(record))
    text = page.render(results)
    assert "growjax 0.0.1" in text and "growjax 0.0.1" not in page.render()


def _environment(version: str, load: float = 0.5) -> dict:
    return {
        "machine": "AMD EPYC 7B13, 2 cores",
        "cpu_model": "AMD EPYC 7B13",
        "cpu_count": 2,
        "load_1min": load,
        "device": "cpu",
        "python": "3",
        "jax": "0",
        "growjax": version,
        "date": "d",
        "command": "python benchmarks/simulate.py --repeat 10",
    }


def _simulate(results: Path, version: str, wall_s: float = 0.012, load: float = 0.5):
    record = {
        "environment": _environment(version, load),
        "simulation": {"wall_s": wall_s, "compile_s": 3.0},
        "gradient": {"wall_s": 0.05, "compile_s": 5.0},
        "targets": {"simulate_s": 0.02, "gradient_s": 0.06},
    }
    (results / "simulate.json").write_text(json.dumps(record))


def _table(page: str, heading: str) -> list[list[str]]:
    """The rows of the table under ``## heading``, as cells."""
    section = page.split(f"## {heading}\n", 1)[1].split("\n## ", 1)[0]
    lines = [line for line in section.splitlines() if line.startswith("| ")][1:]
    return [[c.strip() for c in line.strip("|").split("|")] for line in lines]


def test_benchmarks_page_is_rendered_from_the_committed_files(report):
    assert (REPO / "docs" / "benchmarks.md").read_text() == report.render(), (
        "docs/benchmarks.md differs from its results files: run python benchmarks/report.py"
    )


def test_a_benchmark_figure_reaches_its_topic_with_target_verdict_machine_and_command(report, tmp_path):
    _simulate(tmp_path, report.current_version())
    rows = _table(report.render(tmp_path), "Simulation speed")
    first = rows[0]
    assert first[1:4] == ["12.0 ms", "≤ 20.0 ms", "met"]
    assert first[4] == f"{report.current_version()}; 2 × AMD EPYC 7B13"
    assert first[5] == "`python benchmarks/simulate.py --repeat 10`"
    assert rows[1][1:4] == ["50.0 ms", "≤ 60.0 ms", "met"]


def test_a_missed_time_target_on_a_shared_machine_says_so(report, tmp_path):
    _simulate(tmp_path, report.current_version(), wall_s=0.031, load=9.6)
    first = _table(report.render(tmp_path), "Simulation speed")[0]
    assert first[1] == "31.0 ms" and first[3].startswith("missed: above the target")
    assert "2 cores shared with other work" in first[3] and first[4].endswith("shared: load 9.6")


def test_a_results_file_absent_or_of_another_version_is_not_measured(report, tmp_path):
    """Every topic has a row; no figure of another version reaches the page."""
    empty = report.render(tmp_path)
    for title, _, _ in report.TOPICS:
        assert "not measured for this version" in _table(empty, title)[0][0], title
    _simulate(tmp_path, "0.0.1", wall_s=0.0123)
    page = report.render(tmp_path)
    rows = _table(page, "Simulation speed")
    assert len(rows) == 1 and "another version" in rows[0][0] and rows[0][5] == "`python benchmarks/simulate.py`"
    assert "12.3 ms" not in page


def test_the_benchmarks_page_is_short_and_each_results_file_small(report):
    assert len((REPO / "docs" / "benchmarks.md").read_text().splitlines()) <= 250
    for path in (REPO / "benchmarks" / "results").glob("*.json"):
        assert path.stat().st_size <= 100_000, f"{path.name}: write a compact summary beside the large output"


def test_sweep_resume_rows(report):
    r = {
        "identical": {"all": False, "sweep_csv": True, "store_arrays": {"rmse": False}},
        "ratio_process": 1.3,
        "target_ratio": 1.2,
    }
    same, cost = report.rw.sweep_resume(r)
    assert (same.value, same.met) == ("no", False)
    assert (cost.value, cost.target, cost.met, cost.timed) == ("1.30", "≤ 1.20", False, True)
