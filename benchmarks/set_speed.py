"""The cost of a joint fit against one experiment's, in one process.

Run: ``python benchmarks/set_speed.py [--experiments 8] [--repeat 3] [--out benchmarks/results/set_speed.json]``.

A set of ``--experiments`` reference-made experiments of one robot on one drawn rig (``benchmarks/sets.py``'s sets),
10 s each: ``growjax.calibration.fit`` of the whole set, of its first experiment alone, and
``growjax.calibration.fit`` of that experiment, each ``--repeat`` times, interleaved. Printed: the median warm wall
times and the ratio of the set's to one experiment's (target ≤ 3), with the share spent in the batched simulations;
with ``--each`` (default), ``growjax.calibration.fit`` of every experiment of the set alone, warm, and the ratio of
the set's fit to their mean (the eight experiments' single runs differ up to fourfold in cost, and the first is one of
the cheapest); and one evaluation of the fit's model (residuals and tangents in Y and the rig's errors) for the whole
set in its batched program against that of one experiment, and the set's program on one device.

Every CPU core is a JAX device (``jax_num_cpu_devices``; ``GROWJAX_CPU_DEVICES`` overrides), as in ``growjax fit``,
so the set's runs spread over them.
"""

from __future__ import annotations

import os
import sys

import jax

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _environment import environment, use_all_cpu_cores  # noqa: E402

use_all_cpu_cores()

import argparse
import json
import time
from pathlib import Path

import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax.calibration import batch as cb
from growjax.data import experiment as ex
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from sets import CATHETER, TIME, make_set


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiments", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--each",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also fit every experiment of the set alone (one compile each)",
    )
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "set_speed.json"))
    args = ap.parse_args()
    _, _, exps, status = make_set(np.random.default_rng(args.seed), args.experiments, 1e-6)
    runs = xs.ExperimentSet(tuple(xs.Run(e.source, e) for e in exps))
    first = xs.ExperimentSet(runs.runs[:1])
    config = gj.Config(t1=10.0)
    inputs = _inputs(exps[0])
    jobs = {
        "set": lambda: cal.fit(runs, ["Y@robot"], config=config, starts=1, scout=16),
        "one_experiment_as_a_set": lambda: cal.fit(first, ["Y@robot"], config=config, starts=1, scout=16),
        "one_experiment_fit": lambda: cal.fit(_one(exps[0], inputs), ["Y"], config=config),
    }
    walls = {k: [] for k in jobs}
    simulate = []
    for _ in range(args.repeat):
        for k, job in jobs.items():
            clock = time.perf_counter()
            res = job()
            walls[k].append(time.perf_counter() - clock)
            if k == "set":
                simulate.append(res.simulate_s)
    row = {k: {"first_s": w[0], "warm_s": float(np.median(w[1:] or w))} for k, w in walls.items()}
    row["ratio_set_over_one_fit"] = row["set"]["warm_s"] / row["one_experiment_fit"]["warm_s"]
    if args.each:
        row["each_experiment_fit"] = _each(exps, config, args.repeat)
        row["ratio_set_over_mean_fit"] = row["set"]["warm_s"] / row["each_experiment_fit"]["mean_warm_s"]
    row["set_simulate_share"] = float(np.median(simulate[1:] or simulate) / row["set"]["warm_s"])  # warm runs
    row["evaluation"] = _evaluation(exps, config, args.repeat)
    row["ratio_evaluation_set_over_one"] = row["evaluation"]["set_s"] / row["evaluation"]["one_s"]
    row["devices"] = len(jax.devices())
    print(json.dumps(row, indent=1))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"environment": environment(), "arguments": vars(args), **row}, indent=1))


def _inputs(exp):
    """The inputs of one experiment of the set: its recorded demand, the sets' catheter."""
    return gj.Inputs(
        catheter_length=gj.Sampled(TIME, CATHETER), pressure_demand=gj.Sampled(TIME, exp["pressure_demand_Pa"])
    )


def _one(exp, inputs):
    """The set of one experiment: its length alone, run with ``inputs``."""
    return xs.ExperimentSet.single(ex.from_arrays(TIME, exp["robot_length_m"]), inputs=inputs)


def _each(exps, config, repeat: int) -> dict:
    """Median warm wall time, s, of ``growjax.calibration.fit`` of each experiment of the set alone (its first call
    compiles and is not counted), and their mean: the cost of fitting the set one experiment at a time is
    ``len(exps)`` × that mean."""
    warm = []
    for e in exps:
        inputs = _inputs(e)
        walls = []
        for _ in range(repeat + 1):
            clock = time.perf_counter()
            cal.fit(_one(e, inputs), ["Y"], config=config)
            walls.append(time.perf_counter() - clock)
        warm.append(float(np.median(walls[1:])))
    return {"warm_s": warm, "mean_warm_s": float(np.mean(warm))}


def _evaluation(exps, config, repeat: int) -> dict:
    """Median warm wall time, s, of one linearisation of the default fit's model (Y and the default tolerances): the
    whole set in the joint fit's program (spread over the devices), the same on one device, and its first
    experiment alone in the fit's program."""
    import jax.numpy as jnp

    from growjax.calibration import tolerance as tl
    from growjax.calibration.problem import linearised

    base = gj.reference("forward")
    names = ("robot.yield_pressure", *tl.budget(base, None, ["robot.yield_pressure"], use_default=True))
    cfg = config.replace(adjoint="forward")
    problems = [
        cal.make_problem(
            base, names, ex.to_inputs(e, "forward", base, cfg.t0, cfg.t1), cfg, e.time, e["robot_length_m"]
        )
        for e in exps
    ]
    stacked = cb.stack(cb.pad_breaks(problems))
    z_set, z_one = jnp.zeros((len(exps), len(names))), jnp.zeros(len(names))
    times = {"set_s": [], "set_one_device_s": [], "one_s": []}
    for _ in range(repeat + 1):  # the first call compiles
        for key, call in (
            ("set_s", lambda: cb.spread(cb.linearise_runs, z_set, stacked)),
            ("set_one_device_s", lambda: cb.on_one_device(cb.linearise_runs, z_set, stacked)),
            ("one_s", lambda: linearised(z_one, problems[0])),
        ):
            clock = time.perf_counter()
            jax.block_until_ready(call())
            times[key].append(time.perf_counter() - clock)
    return {k: float(np.median(v[1:])) for k, v in times.items()}


if __name__ == "__main__":
    main()
