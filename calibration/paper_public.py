"""The public MAMMOBOT experiment against the paper: the commands of the Results page's first two sections, run
as a user runs them, their summaries kept for the page.

Run from the repository root::

    python calibration/paper_public.py [--data-dir DIR] [--results calibration/results/paper.json]

``--data-dir`` (default ``$GROWJAX_DATA_DIR``, else ``../shared/data/mammobot`` beside the checkout): a folder
with the public data set's files (see the data page). Runs, each as its own ``growjax`` process with
``--json``:

- ``growjax simulate mammobot --param Y=7920.46``: the forward model at the published parameters;
- ``growjax simulate mammobot --drive inverse --rtol 1e-5``: the stepper model with the shipped step controller;
- ``growjax sweep mammobot --sobol``: the paper's 500-set Latin hypercube and the Sobol indices over its box.

The membrane's safe pressure is the simulations' ``pressure_limit_Pa`` (``gj.pressure_limit``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from growjax.data import experiment as ex

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment

PUBLISHED_Y = "7920.46"  # Pa, the paper's Y
RUNS = {
    "forward": ["simulate", "mammobot", "--param", f"Y={PUBLISHED_Y}"],
    "stepper": ["simulate", "mammobot", "--drive", "inverse", "--rtol", "1e-5"],
    "sweep": ["sweep", "mammobot", "--sobol"],
}


def data_dir(given: str | None) -> Path:
    folder = given or os.environ.get("GROWJAX_DATA_DIR") or ex.shared_experiment_dir()
    if folder is None:
        raise SystemExit("the public data set's files were not found: pass --data-dir DIR")
    return Path(folder)


def run(name: str, args: list[str], folder: Path, tmp: Path) -> dict:
    """One ``growjax`` command; its ``--json`` summary with the command line and the process's wall time."""
    out = tmp / name
    cmd = [
        sys.executable,
        "-m",
        "growjax.cli",
        *args,
        "--data-dir",
        str(folder),
        "--out",
        str(out),
        "--json",
        str(out / "summary.json"),
    ]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")]))}
    clock = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if not (out / "summary.json").exists():
        raise SystemExit(f"growjax {' '.join(args)} failed ({done.returncode}): {done.stderr.strip()[-400:]}")
    summary = json.loads((out / "summary.json").read_text())
    return {
        "command": "growjax " + " ".join(args),
        "exit_status": done.returncode,
        "process_wall_s": time.perf_counter() - clock,
        "summary": summary,
    }


def record(runs: dict) -> dict:
    """The page's figures from the commands' summaries."""
    forward, stepper, sweep = (runs[k]["summary"] for k in ("forward", "stepper", "sweep"))
    return {
        "forward_rmse_m": forward["rmse_length_m"],
        "stepper_rmse_m": stepper["rmse_length_m"],
        "sweep_best": sweep["best"],
        "sweep_n": sweep["n"],
        "sweep_ranges": sweep["ranges"],
        "sobol": sweep["sobol"],
        "pressure_limit_Pa": forward["pressure_limit_Pa"],
        "commands": {
            k: {"command": r["command"], "exit_status": r["exit_status"], "process_wall_s": r["process_wall_s"]}
            for k, r in runs.items()
        },
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--results", default=str(REPO / "calibration" / "results" / "paper.json"))
    args = ap.parse_args(argv)
    folder = data_dir(args.data_dir)
    with tempfile.TemporaryDirectory(prefix="paper_public_") as tmp:
        runs = {}
        for name, cmd in RUNS.items():
            runs[name] = run(name, cmd, folder, Path(tmp))
            print(f"{runs[name]['command']}: {runs[name]['process_wall_s']:.0f} s", flush=True)
    result = {
        "environment": environment(),
        "command": "python calibration/paper_public.py",
        "data": "mammobot",
        **record(runs),
    }
    out = Path(args.results)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
