"""Write docs/benchmarks.md from the results files in benchmarks/results/*.json.

Run: ``python benchmarks/report.py [--results benchmarks/results] [--out docs/benchmarks.md]``, after any of the
benchmark scripts (each writes its results file, with the machine, versions and command it ran with). The results
files are kept in the repository; the page is regenerated from them alone: rerun the scripts, never edit the page.
A results file that is absent, or that another version of growjax wrote, gives its topic a row "not measured for
this version" with the command that measures it.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _rows as rw  # noqa: E402
import _study_rows as st  # noqa: E402
import _track_rows as tr  # noqa: E402
from _rows import Row  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Source:
    """A results file: its name in benchmarks/results, the command that writes it, the rows it gives; ``always``:
    shown as not measured where it is absent (otherwise left out until it exists)."""

    stem: str
    command: str
    rows: Callable[[dict], list[Row]]
    always: bool = True


def _py(script: str, *args: str) -> str:
    return " ".join(["python", f"benchmarks/{script}.py", *args])


def _variant(stem: str, script: str, rows, *args: str) -> Source:
    return Source(stem, _py(script, *args, "--out", f"benchmarks/results/{stem}.json"), rows, always=False)


TOPICS: list[tuple[str, str, list[Source]]] = [
    (
        "Simulation speed",
        "One 10 s simulation of the public experiment (the shipped synthetic one where it is absent), after "
        "compilation; the median of repeated calls.",
        [Source("simulate", _py("simulate"), rw.simulate)],
    ),
    (
        "Fast against reference configuration",
        "The fast configuration's length against the reference's, over the paper's box, both growth laws.",
        [
            Source("agreement", _py("agreement"), rw.agreement),
            _variant("agreement_quick", "agreement", rw.agreement, "--quick"),
        ],
    ),
    (
        "Sweep",
        "A Latin-hypercube sweep over the paper's box (n, Y, ext), every CPU core a JAX device, against a SciPy BDF "
        "baseline; an interrupted `growjax sweep` resumed.",
        [Source("sweep", _py("sweep"), rw.sweep), Source("sweep_resume", _py("sweep_resume"), rw.sweep_resume)],
    ),
    (
        "Fit speed",
        "`growjax.calibration.fit` of Y on 0–10 s, warm (the first call compiles); the least-squares engine against "
        "optimistix's solvers.",
        [
            Source("fit_speed", _py("fit_speed"), rw.fit_speed),
            Source("set_speed", _py("set_speed"), rw.set_speed),
            Source("least_squares", _py("least_squares"), rw.least_squares, always=False),
        ],
    ),
    (
        "Experiment sets",
        "Joint fits of several experiments of one robot on one rig, on reference-made data.",
        [Source("sets", _py("sets"), st.sets), Source("mixed_set", _py("mixed_set"), st.mixed_set)],
    ),
    (
        "Coverage and uncertainty",
        "How often the 90 % intervals and bands contain the truth, on data the fitted model did not make.",
        [
            Source("coverage_discrepancy", _py("coverage_discrepancy"), st.coverage),
            _variant(
                "coverage_discrepancy_default_budget",
                "coverage_discrepancy",
                st.coverage,
                "--groups smooth correlated --budget default",
            ),
            Source("rig_agreement", _py("rig_agreement"), st.rig_agreement),
            Source("windows_public", _py("windows_public"), st.windows),
            Source("predict_public", _py("predict_public"), st.predict),
        ],
    ),
    (
        "Discovery",
        "`growjax.discover` over the whole catalogue on reference-made data: each effect hidden, and clean data.",
        [
            Source("discover", _py("discover"), st.discover),
            Source("discover_discrepancy", _py("discover_discrepancy"), st.discover_discrepancy),
        ],
    ),
    (
        "Experiment design",
        "The designed experiment against random admissible inputs and the published pulse train, with replications "
        "on drawn rigs.",
        [
            Source("design", _py("design"), st.design),
            _variant(
                "design_discrimination",
                "design",
                st.design_discrimination,
                "--discriminate A B --duration 3 --knot-spacing 0.1 --random 16 --replications 10",
            ),
            _variant(
                "design_lockhart",
                "design",
                st.design_lockhart,
                "--growth-law lockhart --for Y phi_L n_L --random 64 --starts 2 --iterations 20",
            ),
        ],
    ),
    (
        "Control",
        "Control designs made on the fast configuration, their tracking evaluated on the reference one.",
        [Source("control", _py("control"), rw.control)],
    ),
    (
        "Tracking",
        "`growjax.track` from the pump's pressure and syringe on records the reference configuration made on rigs "
        "drawn from the default tolerance budget (0.5 kPa, 5 µm); change detection; output feedback on the reference "
        "plant; the public experiment's unrecorded demand.",
        [
            Source("track", _py("track", "--methods", "extended"), tr.track),
            Source(
                "track_walk",
                _py("track", "--methods", "extended", "--walk", "0.04", "--out", "benchmarks/results/track_walk.json"),
                tr.track_walk,
            ),
            Source("track_change", _py("track_change", "--feedback", "0"), tr.track_change),
            Source(
                "track_feedback",
                _py("track_change", "--seeds", "0", "--clean", "0", "--out", "benchmarks/results/track_feedback.json"),
                tr.track_feedback,
            ),
            Source("track_public", _py("track_public"), tr.track_public),
            Source("start_transient", _py("start_transient"), tr.start_transient),
        ],
    ),
    (
        "Populations",
        "Populations of eight robots on one drawn rig, fitted jointly, then the population posterior by NUTS.",
        [Source("population", _py("population"), st.population)],
    ),
]

HEADER = """# Benchmarks

Written by `python benchmarks/report.py` from the results files in `benchmarks/results/`, each written by the
command beside its rows. Times are wall-clock seconds after compilation unless a row says otherwise, on the
machine named in the row; where other work shared it, its load (the one-minute load average as the benchmark
started) is named too, and a missed time target on such a machine says so. A figure that has no target is shown
for information (—).
"""

COLUMNS = "| measured | value | target | met | growjax, machine | command |\n|---|---|---|---|---|---|\n"


def current_version() -> str:
    import growjax

    return growjax.__version__


def _cpu(model: str) -> str:
    """The CPU's model without vendor marks and clock."""
    model = re.sub(r"\((?:R|TM|tm)\)|\bCPU\b|\bProcessor\b|\b\d+-Core\b|@.*$", "", model)
    return re.sub(r"\s+", " ", model).strip()


def loaded(env: dict) -> bool:
    """Whether other work shared the machine: a one-minute load average of at least half its cores."""
    load, cores = env.get("load_1min"), env.get("cpu_count")
    return load is not None and bool(cores) and load >= cores / 2


def machine(env: dict) -> str:
    """growjax's version and the machine: cores, CPU model, device and, where shared, its load."""
    model = _cpu(env.get("cpu_model") or env["machine"].rsplit(",", 1)[0])
    where = f"{env.get('cpu_count', '?')} × {model}" + (f" ({env['device']})" if env.get("device") != "cpu" else "")
    if loaded(env):
        where += f", shared: load {env['load_1min']:.1f}"
    return f"{env['growjax']}; {where}"


def verdict(row: Row, env: dict) -> str:
    if row.met is None:
        return "—"
    if row.met:
        return "met"
    why = row.why
    if row.timed and loaded(env):
        why += f"{'; ' if why else ''}{env['cpu_count']} cores shared with other work"
    return f"missed: {why}" if why else "missed"


def source_rows(source: Source, results: Path, version: str) -> list[str]:
    """The table lines of one results file; one "not measured" line where it is absent or of another version."""
    path = results / f"{source.stem}.json"
    record = json.loads(path.read_text()) if path.is_file() else None
    env = (record or {}).get("environment") or {}
    if record is None or env.get("growjax") != version:
        if record is None and not source.always:
            return []
        what = "no results file" if record is None else "its results file is from another version"
        return [
            f"| {source.stem.replace('_', ' ')}: not measured for this version ({what}) | | | | | `{source.command}` |"
        ]
    try:
        rows = source.rows(record)
    except (KeyError, TypeError, ValueError, IndexError) as err:
        rows = [Row(f"{source.stem.replace('_', ' ')}: results file not readable", type(err).__name__)]
    command = env.get("command", source.command)
    cell = machine(env)
    return [
        f"| {r.measured} | {r.value} | {r.target or '—'} | {verdict(r, env)} | {cell} | `{command}` |" for r in rows
    ]


def render(results: Path | None = None, version: str | None = None) -> str:
    """The page from the results files in ``results`` (default benchmarks/results), for growjax ``version``
    (default the installed one)."""
    results = Path(results) if results else REPO / "benchmarks" / "results"
    version = version or current_version()
    parts = [HEADER]
    for title, what, sources in TOPICS:
        lines = [line for source in sources for line in source_rows(source, results, version)]
        parts.append(f"\n## {title}\n\n{what}\n\n{COLUMNS}" + "\n".join(lines) + "\n")
    return "".join(parts)


def main(argv=None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", default=str(REPO / "benchmarks" / "results"))
    parser.add_argument("--out", default=str(REPO / "docs" / "benchmarks.md"))
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.write_text(render(Path(args.results)))
    print("wrote", out)
    return out


if __name__ == "__main__":
    main()
