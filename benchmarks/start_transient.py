"""The fast configuration against the reference when the demand rises at the very start of a run.

Run: ``python benchmarks/start_transient.py [--out benchmarks/results/start_transient.json]``.

The reference parameters, catheter 4 mm, 1 s: a demand of 160 kPa reached from 0 at t = 0 over 0 s (a step), 10 ms
and 100 ms, the same step at 0.5 s, and the published pulse train (0 kPa until 0.26 s). For each: the length's
difference fast − reference (mm), its RMS over the samples at 10 ms and its value at 1 s. An estimator on the fast
configuration would carry that offset unseen by the pump's sensors, which is why output feedback's loop
(``growjax.control.run_on_estimate``) holds the pump idle over its first tick. Writes the rows with the machine and versions, and prints a table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from _environment import environment  # the script's folder is on the path

import growjax as gj

HERE = Path(__file__).resolve().parent
LEVEL = 160e3  # Pa
T_END = 1.0  # s


def demands() -> dict:
    """{name: demand signal}."""
    grid = np.round(np.arange(0.0, T_END + 1e-9, 1e-3), 9)

    def rising(at: float, over: float):
        values = LEVEL * np.clip((grid - at) / over, 0.0, 1.0) if over > 0 else np.where(grid >= at, LEVEL, 0.0)
        return gj.Sampled(grid, values)

    return {
        "step to 160 kPa at 0 s": gj.Constant(LEVEL),
        "ramp to 160 kPa over 10 ms from 0 s": rising(0.0, 0.01),
        "ramp to 160 kPa over 100 ms from 0 s": rising(0.0, 0.1),
        "step to 160 kPa at 0.5 s": rising(0.5, 0.0),
        "published pulse train (150 kPa)": gj.published_pulse(),
    }


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "results" / "start_transient.json"))
    args = ap.parse_args()
    params = gj.reference("forward")
    ts = np.round(np.arange(1, round(T_END / 0.01) + 1) * 0.01, 9)
    rows = []
    for name, demand in demands().items():
        inputs = gj.Inputs(catheter_length=gj.Constant(0.004), pressure_demand=demand)
        length = {
            fidelity: np.asarray(gj.simulate(params, inputs, gj.Config(fidelity=fidelity, t1=T_END), ts=ts).length)
            for fidelity in ("reference", "fast")
        }
        d = length["fast"] - length["reference"]
        rows.append({"demand": name, "rms_m": float(np.sqrt(np.mean(d**2))), "at_end_m": float(d[-1])})
        print(f"{name:38s} fast − reference: RMS {1e3 * rows[-1]['rms_m']:.3f} mm, at 1 s {1e3 * d[-1]:+.3f} mm")
    res = {"environment": environment(), "level_Pa": LEVEL, "t_end_s": T_END, "rows": rows}
    Path(args.out).write_text(json.dumps(res, indent=1))
    print(f"wrote {args.out}")
    return res


if __name__ == "__main__":
    main()
