"""Golden comparison: every command's ``--json`` summary on the shipped data, recorded and compared.

Record a tree's figures, then compare two records::

    python benchmarks/golden.py record DIR            # runs each command of CASES, writes DIR/<case>.json
    python benchmarks/golden.py compare BEFORE AFTER  # prints the table, writes AFTER/comparison.json

Every numeric leaf of each summary is compared, except times, paths and the like (:data:`IGNORED`). A leaf agrees
when it matches to :data:`RTOL` relative or :data:`ATOL` absolute; the table lists each case's headline figures,
how many leaves it has and how many moved, and the largest relative move.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "src" / "growjax" / "data" / "datasets"

# case: (command line after `growjax`, headline figures as dotted paths into the summary)
CASES = {
    "simulate": (["simulate"], ["final_length_m", "peak_pressure_Pa", "rmse_length_m", "solver_steps"]),
    "sweep": (["sweep", "--sets", "50"], ["best.rmse_length_m", "best.Y", "n_failed"]),
    "fit": (
        ["fit"],
        ["parameters.robot.yield_pressure.estimate", "parameters.robot.yield_pressure.interval_90", "rmse_length_m"],
    ),
    "fit_none": (
        ["fit", "--discrepancy", "none"],
        ["parameters.robot.yield_pressure.estimate", "parameters.robot.yield_pressure.interval_90"],
    ),
    "fit_set": (
        ["fit", str(DATA / "set" / "set.toml")],
        [
            "parameters.robot.yield_pressure@membrane-1.estimate",
            "parameters.robot.yield_pressure@membrane-1.interval_90",
        ],
    ),
    "posterior": (
        ["posterior", "--emulate", "--chains", "2", "--warmup", "150", "--samples", "150"],
        ["parameters.Y.median", "parameters.Y.interval_90"],
    ),
    "posterior_none": (
        ["posterior", "--emulate", "--chains", "2", "--warmup", "150", "--samples", "150", "--discrepancy", "none"],
        ["parameters.Y.median", "parameters.Y.interval_90"],
    ),
    "population": (
        [
            "posterior",
            str(DATA / "population" / "population.toml"),
            "--hierarchical",
            "Y",
            "--chains",
            "1",
            "--warmup",
            "100",
            "--samples",
            "100",
        ],
        ["mu.median", "spread.median"],
    ),
    "discover": (["discover", str(DATA / "discovery" / "retraction_folding.csv")], ["effect", "verdict"]),
    "discover_set": (
        ["discover", str(DATA / "discovery_set" / "set.toml"), "--candidates", "retraction_folding,trapped_air"],
        ["effect", "verdict"],
    ),
    "control": (["control"], ["tracking_rmse_m", "peak_pressure_Pa"]),
    "design": (
        [
            "design",
            "--duration",
            "3",
            "--scout",
            "8",
            "--descent-steps",
            "2",
            "--check-draws",
            "4",
            "--criterion-points",
            "1",
            "--nonlinear-draws",
            "0",
        ],
        ["criterion", "table"],
    ),
}
IGNORED = (
    "wall_s",
    "_s",
    "first_call",
    "figure",
    "csv",
    "file",
    "store",
    "data",
    "path",
    "json",
    "text",
    "n_devices",
    "device",
    "trace_lower",
    "compile",
    "process",
)
RTOL, ATOL = 1e-6, 1e-12


def record(where: Path, cases) -> None:
    where.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "GROWJAX_CACHE_DIR": str(where / "jax_cache")}
    for name in cases:
        line, _ = CASES[name]
        out = where / "out" / name
        cmd = [sys.executable, "-m", "growjax.cli", *line, "--out", str(out), "--json", str(where / f"{name}.json")]
        if line[0] in ("sweep", "fit", "posterior", "discover", "design", "control"):
            cmd.append("--quiet")
        clock = time.perf_counter()
        done = subprocess.run(cmd, env=env, capture_output=True, text=True)
        print(f"{name}: exit {done.returncode} in {time.perf_counter() - clock:.0f} s", flush=True)
        if done.returncode not in (0, 1):
            print(done.stderr[-2000:], file=sys.stderr)
        (where / f"{name}.command").write_text(" ".join(["growjax", *line]) + f"\nexit {done.returncode}\n")


def _leaves(x, path=""):
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _leaves(v, f"{path}.{k}" if path else str(k))
    elif isinstance(x, (list, tuple)):
        for i, v in enumerate(x):
            yield from _leaves(v, f"{path}[{i}]")
    else:
        yield path, x


def _ignored(path: str) -> bool:
    last = path.split(".")[-1].split("[")[0]
    return any(last.endswith(s) or s in last for s in IGNORED)


def _get(summary, dotted: str):
    """The value at ``dotted`` (keys may themselves hold dots: the longest key that matches is taken)."""
    x, rest = summary, dotted
    while rest:
        if not isinstance(x, dict):
            return None
        key = next((k for k in sorted(x, key=len, reverse=True) if rest == k or rest.startswith(k + ".")), None)
        if key is None:
            return None
        x, rest = x[key], rest[len(key) + 1 :]
    return x


def _show(x) -> str:
    if isinstance(x, float):
        return f"{x:.6g}"
    if isinstance(x, list):
        return "[" + ", ".join(_show(v) for v in x) + "]"
    if isinstance(x, dict):
        return "{…}"
    return str(x)


def compare(before: Path, after: Path) -> dict:
    rows = {}
    for name, (_, headline) in CASES.items():
        a, b = before / f"{name}.json", after / f"{name}.json"
        if not (a.is_file() and b.is_file()):
            continue
        old, new = json.loads(a.read_text()), json.loads(b.read_text())
        old_leaves = {p: v for p, v in _leaves(old) if not _ignored(p)}
        new_leaves = {p: v for p, v in _leaves(new) if not _ignored(p)}
        moved, worst, missing = [], 0.0, sorted(set(old_leaves) - set(new_leaves))
        for p, v in old_leaves.items():
            if p not in new_leaves:
                continue
            w = new_leaves[p]
            if isinstance(v, (int, float)) and isinstance(w, (int, float)) and not isinstance(v, bool):
                diff = abs(float(w) - float(v))
                rel = diff / max(abs(float(v)), 1e-300)
                if diff > ATOL and rel > RTOL:
                    moved.append((p, v, w, rel))
                    worst = max(worst, rel)
            elif v != w:
                moved.append((p, v, w, None))
        rows[name] = {
            "headline": {h: [_get(old, h), _get(new, h)] for h in headline},
            "leaves": len(old_leaves),
            "moved": [(p, v, w, r) for p, v, w, r in moved],
            "missing": missing,
            "largest_relative_move": worst,
        }
    return rows


def table(rows: dict) -> str:
    out = [
        "| case | figure | before | after | leaves | moved | largest relative move |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in rows.items():
        first = True
        for h, (old, new) in r["headline"].items():
            extra = f"{r['leaves']} | {len(r['moved'])} | {r['largest_relative_move']:.1e}" if first else " | | "
            out.append(f"| {name if first else ''} | {h} | {_show(old)} | {_show(new)} | {extra} |")
            first = False
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("where", type=Path)
    rec.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    cmp_ = sub.add_parser("compare")
    cmp_.add_argument("before", type=Path)
    cmp_.add_argument("after", type=Path)
    args = ap.parse_args(argv)
    if args.what == "record":
        record(args.where, args.cases)
        return 0
    rows = compare(args.before, args.after)
    print(table(rows))
    for name, r in rows.items():
        for p, v, w, rel in r["moved"][:12]:
            print(f"  {name}: {p}: {_show(v)} -> {_show(w)}" + (f" ({rel:.1e})" if rel is not None else ""))
        if r["missing"]:
            print(f"  {name}: missing after: {', '.join(r['missing'][:8])}")
    (args.after / "comparison.json").write_text(json.dumps(rows, indent=1, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
