"""The generated pages: docs/results.md is what calibration/results_page.py renders from the committed results
files, of one version of growjax, and benchmarks/report.py keeps the sections whose results file is absent."""

import importlib.util
import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
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


def test_results_page_refuses_files_of_two_versions(page, tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    for f in (REPO / "calibration" / "results").glob("*.json"):
        (results / f.name).write_text(f.read_text())
    record = json.loads((results / "paper.json").read_text())
    record["environment"]["growjax"] = "0.0.1"
    (results / "paper.json").write_text(json.dumps(record))
    with pytest.raises(SystemExit, match="rerun the older script"):
        page.render(results)


def _result(stem: str, results: Path, **extra):
    env = {"machine": "m", "device": "cpu", "python": "3", "jax": "0", "growjax": "0", "date": "d"}
    (results / f"{stem}.json").write_text(json.dumps({"environment": env, **extra}))


def test_report_keeps_sections_whose_results_file_is_absent(report, tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    _result("alpha", results, x=1.0)
    _result("gamma", results, y=2.0)
    out = tmp_path / "page.md"
    report.main(["--results", str(results), "--out", str(out)])
    (results / "gamma.json").unlink()
    _result("beta", results, z=3.0)
    report.main(["--results", str(results), "--out", str(out)])
    kept = report.sections(out.read_text())
    assert list(kept) == ["alpha", "beta", "gamma"]
    assert report.table_rows(kept["gamma"]) == [["y", "2", ""]]
    report.main(["--results", str(results), "--out", str(out), "--drop-missing"])
    assert list(report.sections(out.read_text())) == ["alpha", "beta"]


def test_report_page_round_trips(report):
    """Splitting the Benchmarks page into its sections and joining them back gives the page."""
    text = (REPO / "docs" / "benchmarks.md").read_text()
    assert report.render(REPO / "no-such-folder", report.sections(text)) == text


def test_sweep_resume_rows(report):
    r = {
        "uninterrupted": {"process_wall_s": 40.0, "sweep_wall_s": 30.0},
        "interrupted": {"chunks_done": 10, "exit_status": 130},
        "resumed": {"process_wall_s": 24.0, "sweep_wall_s": 16.5},
        "identical": {"all": False, "sweep_csv": True, "store_arrays": {"rmse": False}},
        "chunks": 20,
        "n": 5000,
        "chunk_size": 250,
        "n_devices": 2,
        "remaining_share": 0.5,
        "ratio_process": 1.2,
        "ratio_sweep_loop": 1.1,
        "target_ratio": 1.2,
    }
    rows = {a: (b, c) for a, b, c in report.rows_sweep_resume(r)}
    assert rows["resumed table identical to the uninterrupted one"][0] == "no"
    assert "arrays different" in rows["resumed table identical to the uninterrupted one"][1]
    assert rows["chunks done when the SIGINT stopped it"][0] == "10 of 20"
    assert rows["R ÷ (remaining share f × T)"] == ("1.20", "f = 0.50; sweep loops alone 1.10; target ≤ 1.2")
