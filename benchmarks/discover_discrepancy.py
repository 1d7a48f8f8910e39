"""Discovery on data with no catalogue effect but a discrepancy the model does not have: is the answer `none`?

Run: ``python benchmarks/discover_discrepancy.py [--t-end 10] [--out benchmarks/results/discover_discrepancy.json]``.

Twenty reference-made data sets (the shipped reference traces of the published pulse, or new reference runs),
each with one of: a smooth perturbation from outside the catalogue (squared-exponential, 0.02–0.1 mm RMS) plus
0.2 mm white noise; one rig parameter 10 % off (a new reference run) plus the white noise; correlated sensor
noise (AR(1), 0.2 s, 0.2 mm sd). ``growjax.discover`` tests the whole catalogue under the default likelihood and,
for comparison, under independent noise. Target: ``none`` on at least 19 of 20.
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
from growjax import discover as gd
from growjax.calibration import Likelihood
from growjax.data import experiment as ex
from growjax.data.sets import ExperimentSet

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment

sys.path.insert(0, str(REPO / "data"))
sys.path.insert(0, str(REPO / "benchmarks"))
import coverage_discrepancy as cd
import make_synthetic as mk

OFF = [
    ("pid.proportional", 1.1),
    ("pump.screw_viscous_friction", 0.9),
    ("tank.length", 1.1),
    ("robot.catheter_friction", 1.1),
    ("pid.integral", 0.9),
    ("pump.syringe_area", 1.1),
]


def rig_off(t, y):
    base, inputs = mk.case_parameters({}), mk.reference_inputs("published")
    config = gj.Config(fidelity="reference", t1=float(t[-1]))
    ts = jnp.asarray(np.concatenate([[config.t0], t]))

    def run(k):
        p = gj.replace(
            base, Y=y, **{name: gj.get(base, name) * jnp.where(k == i, f, 1.0) for i, (name, f) in enumerate(OFF)}
        )
        return gj.simulate(p, inputs, config, ts=ts).length[1:]

    return np.asarray(jax.jit(jax.vmap(run))(jnp.arange(len(OFF))))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=10.0, help="end of the scored window, s")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--compare", action="store_true", help="also run discovery under independent noise")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "discover_discrepancy.json"))
    args = ap.parse_args()
    clock = time.perf_counter()
    t, lengths, cases = mk.read_reference_lengths()
    keep = t <= args.t_end + 1e-9
    inputs = mk.reference_inputs("published")
    config = gj.Config(t1=float(t[keep][-1]))
    rng = np.random.default_rng(args.seed)
    published = [k for k, c in cases.items() if c["demand"] == "published" and set(c["parameters"]) == {"Y"}]
    sets = []
    for k in range(7):
        name = published[k % len(published)]
        size = (2e-5, 5e-5, 1e-4)[k % 3]
        extra = cd.smooth_perturbation(rng, t[keep], size, (0.5, 1.0, 3.0)[k % 3])
        sets.append((f"smooth {1e3 * size:.2f} mm", lengths[name][keep] + extra + rng.normal(0, 2e-4, keep.sum())))
    for k in range(7):
        name = published[(k + 7) % len(published)]
        sets.append(("correlated 0.20 mm", lengths[name][keep] + cd.ar1(rng, t[keep], 2e-4, 0.2)))
    for k, trace in enumerate(rig_off(t, 9000.0)):
        sets.append((f"{OFF[k][0]} x{OFF[k][1]:g}", trace[keep] + rng.normal(0, 2e-4, keep.sum())))
    rows = []
    for label, data in sets:
        row = {"data": label}
        for kind in ("matern32", "none") if args.compare else ("matern32",):
            one = ExperimentSet.single(ex.from_arrays(t[keep], data), inputs=inputs)
            res = gd.discover(one, config=config, likelihood=Likelihood(discrepancy=kind))
            row[kind] = {
                "effect": res.effect,
                "effects": res.effects,
                "confounded": list(res.confounded_with),
                "wall_s": res.wall_s,
            }
        rows.append(row)
        other = f" (independent noise: {row['none']['effect']})" if args.compare else ""
        print(f"{label:34s}: {row['matern32']['effect']:14s}{other}", flush=True)
    none = sum(r["matern32"]["effect"] == "none" for r in rows)
    none_iid = sum(r["none"]["effect"] == "none" for r in rows) if args.compare else None
    print(f"none on {none} of {len(rows)} (independent noise: {none_iid}); target >= 19 of 20")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "environment": environment(),
                "t_end_s": args.t_end,
                "none": none,
                "none_independent": none_iid,
                "sets": len(rows),
                "rows": rows,
                "wall_s": time.perf_counter() - clock,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
