"""Joint fits of experiment sets: coverage of Y and the gain over single experiments, with the rig's errors shared
by the set's experiments (the default) and, for contrast, taken as independent per experiment.

Run: ``python benchmarks/sets.py [--sets 30] [--experiments 4] [--workers 1] [--resume]
[--out benchmarks/results/sets.json]``; ``--resume`` keeps the sets already in the partial file.
Each experiment alone is fitted as ``growjax fit`` fits it (the rig's errors in the model's tangents);
``--relinearise-singles`` fits it with the rig's secants instead, taken again where the data put the rig
(``rig_tangents=False, relinearise=True``); ``--joint-from FILE`` takes the joint fits from an earlier
results file of the same study and runs the single fits only.

Each set: one robot (Y uniform on 6–12 kPa) on one rig drawn from the default tolerance budget, run under
``--experiments`` seeded random pulse trains (amplitude 80–180 kPa, period 1–2.5 s, duty 40–90 %, delay
0.1–0.5 s, given to the controller as sampled every 10 ms, as a CSV records them), 10 s each, made by the
reference configuration; 0.2 mm white length noise. Fitted by the fast configuration under the default
likelihood: jointly (``Y@robot``, the rig inferred, one error vector for the rig), jointly with
``rig_errors="experiment"``, and each experiment alone. Targets: the joint interval covers the true Y in
0.80–0.97 of the sets and is narrower than the best single experiment's in ≥ 90 % of them; the independent
treatment under-covers.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax.calibration import tolerance as tl
from growjax.data import experiment as ex
from growjax.data import sets as xs
from growjax.data.experiment import Experiment

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment

Y = "robot.yield_pressure"
NOISE = 2e-4  # m
TIME = np.round(np.arange(1, 1001) * 0.01, 10)  # s
CATHETER = 0.004 + 0.004 * TIME  # m


def demands(rng, k: int) -> np.ndarray:
    """(k, T) seeded random pulse trains sampled on TIME, Pa."""
    out = []
    for _ in range(k):
        train = gj.PulseTrain(
            rng.uniform(80e3, 180e3), rng.uniform(1.0, 2.5), rng.uniform(0.4, 0.9), rng.uniform(0.1, 0.5)
        )
        out.append(np.asarray(train(jnp.asarray(TIME))))
    return np.stack(out)


def make_set(rng, k: int, rtol: float):
    """(true Y, rig offsets {name: ln}, [Experiment] k, statuses): one robot on one drawn rig, k demands."""
    base = gj.reference("forward")
    y = float(rng.uniform(6e3, 12e3))
    offsets = {n: float(rng.normal(0.0, u)) for n, u in tl.default_budget(base).items()}
    truth = gj.replace(base, Y=y, **{n: gj.get(base, n) * np.exp(b) for n, b in offsets.items()})
    cols = demands(rng, k)
    config = gj.Config(fidelity="reference", t1=10.0, rtol=rtol, atol=rtol)
    ts = jnp.asarray(np.concatenate([[config.t0], TIME]))

    inputs = [
        gj.Inputs(
            catheter_length=gj.Sampled(jnp.asarray(TIME), jnp.asarray(CATHETER)),
            pressure_demand=gj.Sampled(jnp.asarray(TIME), jnp.asarray(c)),
        )
        for c in cols
    ]
    breaks = [gj.input_breaks(i, config) for i in inputs]  # concrete: found before the batch is traced
    sizes = [max(b[j].size for b in breaks) for j in range(2)]
    breaks = tuple(
        jnp.stack([jnp.concatenate([b[j], jnp.full(sizes[j] - b[j].size, config.t1 + 1.0)]) for b in breaks])
        for j in range(2)
    )
    stacked = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *inputs)

    def run(inp, jumps, kinks):
        traj = gj.simulate(truth, inp, config, ts=ts, breaks=(jumps, kinks))
        return traj.length[1:], traj.status

    lengths, status = jax.jit(jax.vmap(run))(stacked, *breaks)
    lengths = np.asarray(lengths) + rng.normal(0.0, NOISE, (k, TIME.size))
    exps = [
        Experiment(
            TIME, {"robot_length_m": lengths[i], "catheter_length_m": CATHETER, "pressure_demand_Pa": cols[i]}, f"e{i}"
        )
        for i in range(k)
    ]
    return y, offsets, exps, np.asarray(status)


def row_of(lo, hi, truth, estimate):
    return {
        "estimate_Pa": estimate,
        "interval_90_Pa": [lo, hi],
        "width_Pa": hi - lo,
        "covered": bool(lo <= truth <= hi),
    }


def one_set(task):
    """One set's row (None where a reference run failed): the set drawn from its own seeded stream."""
    seed, s, experiments, rtol, relinearise, kept = task
    rng = np.random.default_rng([seed, s])
    config = gj.Config(t1=10.0)
    y, offsets, exps, status = make_set(rng, experiments, rtol)
    if np.any(status != gj.OK):
        return None
    runs = xs.ExperimentSet(tuple(xs.Run(e.source, e) for e in exps))
    row = {
        "set": s,
        "study": [seed, experiments, rtol],
        "truth_Pa": y,
        "rig_offsets": offsets,
        "singles_relinearised": relinearise,
    }
    for label, options in (
        ("joint", {}),
        ("joint_independent_rig", {"likelihood": cal.Likelihood(rig_errors="experiment")}),
    ):
        if kept is not None:
            row[label] = kept[label]
            continue
        t0 = time.perf_counter()
        res = cal.fit(runs, ["Y@robot"], config=config, starts=1, scout=16, **options)
        lab = f"{Y}@robot"
        row[label] = {
            **row_of(*res.interval_90[lab], y, res.estimate[lab]),
            "wall_s": time.perf_counter() - t0,
            "simulate_s": res.simulate_s,
        }
    singles = []
    for run in runs:
        t0 = time.perf_counter()
        inputs = gj.Inputs(
            catheter_length=gj.Sampled(TIME, CATHETER),
            pressure_demand=gj.Sampled(TIME, run.experiment["pressure_demand_Pa"]),
        )
        res = cal.fit(
            xs.ExperimentSet.single(ex.from_arrays(TIME, run.length), inputs=inputs),
            ["Y"],
            config=config,
            starts=1,
            scout=16,
            **({"rig_tangents": False, "relinearise": True} if relinearise else {}),
        )
        singles.append(
            {
                **row_of(*res.interval_90[Y], y, res.estimate[Y]),
                "wall_s": time.perf_counter() - t0,
                "linearisations": res.linearisations,
            }
        )
    row["single"] = singles
    row["joint_narrower_than_best_single"] = bool(row["joint"]["width_Pa"] < min(x["width_Pa"] for x in singles))
    return row


def _z(row: dict, truth: float) -> float:
    """(estimate − truth) / sd, the sd read off the 90 % interval's width (± 1.645 sd)."""
    return (row["estimate_Pa"] - truth) / (row["width_Pa"] / (2 * cal.Z90))


def _kept(partial: Path, args) -> list[dict]:
    """Rows of an earlier run of the same study (same seed, experiments and tolerance) from its partial file."""
    rows = [json.loads(line) for line in partial.read_text().splitlines() if line.strip()] if partial.exists() else []
    same = [
        r
        for r in rows
        if r.get("study") == [args.seed, args.experiments, args.rtol]
        and r.get("singles_relinearised", False) == args.relinearise_singles
    ]
    if len(same) != len(rows):
        raise SystemExit(
            f"{partial}: rows from another study (seed, experiments, rtol or single fits differ); not resumed"
        )
    return same


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=30)
    ap.add_argument("--experiments", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rtol", type=float, default=1e-6, help="the reference configuration's tolerance")
    ap.add_argument("--workers", type=int, default=1, help="sets run at a time, one process each")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "sets.json"))
    ap.add_argument("--resume", action="store_true", help="keep the sets already in the partial file; run the rest")
    ap.add_argument(
        "--relinearise-singles",
        action="store_true",
        help="fit each experiment alone with the rig's secants, linearised again where the data put the "
        "rig (without it: as growjax fit, the rig's errors in the model's tangents)",
    )
    ap.add_argument(
        "--joint-from",
        default=None,
        metavar="SETS.json",
        help="the joint fits from this earlier results file of the same study; run the single fits only",
    )
    args = ap.parse_args()
    joint_rows = {}
    if args.joint_from:
        earlier = json.loads(Path(args.joint_from).read_text())
        joint_rows = {
            r["set"]: r for r in earlier["rows"] if r.get("study") == [args.seed, args.experiments, args.rtol]
        }
        if not joint_rows:
            raise SystemExit(f"{args.joint_from}: no sets of this study (seed, experiments, rtol)")
    clock = time.perf_counter()
    partial = Path(args.out).with_suffix(".partial.jsonl")  # rows as they finish, kept if the run is cut short
    partial.parent.mkdir(parents=True, exist_ok=True)
    rows = _kept(partial, args) if args.resume else []
    if not args.resume:
        partial.write_text("")
    done = {r["set"] for r in rows}
    tasks = [
        (args.seed, s, args.experiments, args.rtol, args.relinearise_singles, joint_rows.get(s))
        for s in range(args.sets)
        if s not in done and (not joint_rows or s in joint_rows)
    ]

    def keep(s, row):
        if row is None:
            print(f"set {s}: a reference run failed; skipped", flush=True)
            return
        rows.append(row)
        with partial.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        j, i = row["joint"], row["joint_independent_rig"]
        singles = row["single"]
        print(
            f"set {s:2d} Y {row['truth_Pa']:7.0f}: joint [{j['interval_90_Pa'][0]:.0f}, {j['interval_90_Pa'][1]:.0f}] "
            f"{j['wall_s']:.0f} s; independent rig [{i['interval_90_Pa'][0]:.0f}, {i['interval_90_Pa'][1]:.0f}]; "
            f"best single width {min(x['width_Pa'] for x in singles):.0f} Pa "
            f"(single fits {sum(x['wall_s'] for x in singles):.0f} s)",
            flush=True,
        )

    if args.workers > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as pool:
            for t, row in zip(tasks, pool.map(one_set, tasks)):
                keep(t[1], row)
    else:
        for t in tasks:
            keep(t[1], one_set(t))
    rows.sort(key=lambda r: r["set"])
    summary = {"sets": len(rows)}
    for label in ("joint", "joint_independent_rig"):
        summary[label] = {
            "coverage_90": float(np.mean([r[label]["covered"] for r in rows])),
            "median_width_Pa": float(np.median([r[label]["width_Pa"] for r in rows])),
            "median_wall_s": float(np.median([r[label]["wall_s"] for r in rows])),
        }
    summary["single"] = {
        "coverage_90": float(np.mean([x["covered"] for r in rows for x in r["single"]])),
        "median_width_Pa": float(np.median([x["width_Pa"] for r in rows for x in r["single"]])),
        "median_wall_s": float(np.median([x["wall_s"] for r in rows for x in r["single"]])),
    }
    summary["joint_narrower_than_best_single"] = float(np.mean([r["joint_narrower_than_best_single"] for r in rows]))
    beaten = [
        (min(r["single"], key=lambda x: x["width_Pa"]), r["truth_Pa"])
        for r in rows
        if not r["joint_narrower_than_best_single"]
    ]  # the single experiment narrower than the joint
    summary["narrower_single"] = {
        "sets": len(beaten),
        "covered": int(sum(x["covered"] for x, _ in beaten)),
        "median_abs_z": float(np.median([abs(_z(x, y)) for x, y in beaten])) if beaten else None,
    }
    for label in ("joint", "joint_independent_rig"):
        summary[label]["rms_z"] = float(np.sqrt(np.mean([_z(r[label], r["truth_Pa"]) ** 2 for r in rows])))
    summary["single"]["rms_z"] = float(np.sqrt(np.mean([_z(x, r["truth_Pa"]) ** 2 for r in rows for x in r["single"]])))
    print(json.dumps(summary, indent=1))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "environment": environment(),
                "arguments": vars(args),
                "summary": summary,
                "rows": rows,
                "wall_s": time.perf_counter() - clock,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
