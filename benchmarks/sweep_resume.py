"""An interrupted ``growjax sweep`` resumed, against the same sweep uninterrupted: identical tables, and the cost
of resuming against the share of the work left.

Run: ``python benchmarks/sweep_resume.py [--n 5000] [--chunks 20] [--data CSV] [--out benchmarks/results/sweep_resume.json]``.

Three ``growjax sweep`` processes (the command line, as a user runs it) on the shipped synthetic experiment
(or ``--data``), ``--n`` sets in ``--chunks`` chunks, sharing one persistent compilation cache that a
one-chunk run of the same sweep has filled first (so every timed process starts alike, warm):

1. the sweep uninterrupted into one folder: its process wall time T;
2. the same command into another folder, SIGINT once about half its chunks are in the store (the store
   polled); the chunks done when it stopped;
3. ``growjax sweep --resume`` on that folder: its process wall time R.

Recorded: the remaining share f (chunks left at the interruption over all chunks), R / (f·T) (target ≤ 1.2),
the same ratio for the sweep loops alone (the summaries' ``wall_s``), and whether the two tables
(``sweep.csv`` and the stores' arrays) are identical bit for bit.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _environment import environment  # benchmarks/ is on sys.path when run as a script

from growjax import sweep as sw
from growjax.sweep.store import StoreError, done_chunks

REPO = Path(__file__).resolve().parents[1]
TARGET_RATIO = 1.2


def command(args, out: Path, *extra: str) -> list[str]:
    data = [args.data] if args.data else []
    return [
        sys.executable,
        "-m",
        "growjax.cli",
        "sweep",
        *data,
        "--sets",
        str(args.n),
        "--chunk-size",
        str(chunk_size(args)),
        "--out",
        str(out),
        "--json",
        str(out / "summary.json"),
        "--quiet",
        *extra,
    ]


def chunk_size(args) -> int:
    return math.ceil(args.n / args.chunks)


def chunks_done(store: Path, chunk: int) -> int:
    """Chunks whose rows are all in ``store`` (0 while it is not there or is being written)."""
    if not store.exists():
        return 0
    try:
        return int(done_chunks(sw.load(store).status, chunk).sum())
    except (StoreError, KeyError, OSError, ValueError):
        return 0


def timed(cmd: list[str], env: dict) -> tuple[float, int]:
    clock = time.perf_counter()
    rc = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL).returncode
    return time.perf_counter() - clock, rc


def interrupted(cmd: list[str], env: dict, store: Path, chunk: int, total: int, poll_s: float) -> dict:
    """Run ``cmd``, SIGINT it once half of ``total`` chunks are in ``store``; what it left."""
    clock = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL)
    while proc.poll() is None and chunks_done(store, chunk) < total / 2:
        time.sleep(poll_s)
    at_signal = chunks_done(store, chunk)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    rc = proc.wait()
    return {
        "chunks_done_at_signal": at_signal,
        "chunks_done": chunks_done(store, chunk),
        "exit_status": rc,
        "process_wall_s": time.perf_counter() - clock,
    }


def identical(a: Path, b: Path) -> dict:
    """Whether two finished sweeps' tables are the same bit for bit: the CSV files and the stores' arrays."""
    ra, rb = sw.load(a / "sweep.zarr"), sw.load(b / "sweep.zarr")
    same = {
        k: np.array_equal(getattr(ra, k), getattr(rb, k), equal_nan=k != "status")
        for k in ("values", "rmse", "final_length", "status")
    }
    return {
        "sweep_csv": (a / "sweep.csv").read_bytes() == (b / "sweep.csv").read_bytes(),
        "store_arrays": same,
        "all": (a / "sweep.csv").read_bytes() == (b / "sweep.csv").read_bytes() and all(same.values()),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=5000, help="sets in the sweep")
    ap.add_argument("--chunks", type=int, default=20, help="chunks the sweep is cut into (--chunk-size n/chunks)")
    ap.add_argument("--data", default=None, help="experiment CSV (default: the shipped synthetic one)")
    ap.add_argument("--poll", type=float, default=0.1, help="s between looks at the store")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "sweep_resume.json"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="sweep_resume_") as tmp:
        tmp = Path(tmp)
        env = {
            **os.environ,
            "GROWJAX_CACHE_DIR": str(tmp / "cache"),
            "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")])),
        }
        warm_s, _ = timed(command(args, tmp / "warm", "--max-chunks", "1"), env)
        print(f"cache filled by a one-chunk run: {warm_s:.1f} s", flush=True)
        full_s, rc_full = timed(command(args, tmp / "full"), env)
        total = -(-args.n // chunk_size(args))
        print(f"uninterrupted: {full_s:.1f} s (exit {rc_full}), {total} chunks", flush=True)
        stop = interrupted(
            command(args, tmp / "cut"), env, tmp / "cut" / "sweep.zarr", chunk_size(args), total, args.poll
        )
        print(f"interrupted: {json.dumps(stop)}", flush=True)
        resume_cmd = [
            sys.executable,
            "-m",
            "growjax.cli",
            "sweep",
            "--resume",
            str(tmp / "cut"),
            "--json",
            str(tmp / "cut" / "summary.json"),
            "--quiet",
        ]
        resume_s, rc_resume = timed(resume_cmd, env)
        print(f"resumed: {resume_s:.1f} s (exit {rc_resume})", flush=True)
        share = (total - stop["chunks_done"]) / total
        full_sum = json.loads((tmp / "full" / "summary.json").read_text())
        resume_sum = json.loads((tmp / "cut" / "summary.json").read_text())
        result = {
            "environment": environment(),
            "arguments": vars(args),
            "data": full_sum["data"],
            "n": args.n,
            "chunks": total,
            "chunk_size": chunk_size(args),
            "n_devices": full_sum["n_devices"],
            "cache_fill_s": warm_s,
            "uninterrupted": {
                "process_wall_s": full_s,
                "exit_status": rc_full,
                "sweep_wall_s": full_sum["wall_s"],
                "compile_s": full_sum["compile_s"],
            },
            "interrupted": stop,
            "resumed": {
                "process_wall_s": resume_s,
                "exit_status": rc_resume,
                "sweep_wall_s": resume_sum["wall_s"],
                "compile_s": resume_sum["compile_s"],
            },
            "remaining_share": share,
            "ratio_process": resume_s / (share * full_s),
            "ratio_sweep_loop": resume_sum["wall_s"] / (share * full_sum["wall_s"]),
            "target_ratio": TARGET_RATIO,
            "identical": identical(tmp / "full", tmp / "cut"),
        }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({k: result[k] for k in ("remaining_share", "ratio_process", "ratio_sweep_loop", "identical")}))
    print("wrote", out)


if __name__ == "__main__":
    main()
