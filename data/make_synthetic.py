"""Make the small synthetic experiments shipped in data/ (and with the package).

Run from the repository root: ``python data/make_synthetic.py``. Deterministic:
seed 20261121. Ground truth and noise are written beside each CSV as JSON.

synthetic_forward.csv — forward drive (published 0/150 kPa pulse, shipped PID),
reference parameters except Y = 9000 Pa, catheter length 4 mm + 4 mm/s·t,
0.01–10 s at 100 Hz; Gaussian noise σ = 0.2 mm on length, σ = 500 Pa on pressure.
"""

from __future__ import annotations

import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import experiment as ex

SEED = 20261121
HERE = Path(__file__).resolve().parent
TRUTH = {"Y": 9000.0}
NOISE = {"robot_length_m": 2e-4, "pressure_Pa": 500.0}


def make_forward(path: Path = HERE / "synthetic_forward.csv") -> Path:
    time = np.round(np.arange(1, 1001) * 0.01, 10)
    catheter = 0.004 + 0.004 * time
    params = gj.replace(gj.reference("forward"), **TRUTH)
    inputs = gj.Inputs(catheter_length=gj.Sampled(jnp.asarray(time), jnp.asarray(catheter)), pressure_demand=gj.published_pulse())
    config = gj.Config(t1=float(time[-1]), rtol=1e-7, atol=1e-7)
    ts = np.concatenate([[config.t0], time])
    traj = gj.simulate(params, inputs, config, ts=ts)
    assert int(traj.status) == gj.OK, gj.status_name(traj.status)
    rng = np.random.default_rng(SEED)
    length = np.asarray(traj.length)[1:] + rng.normal(0.0, NOISE["robot_length_m"], time.size)
    pressure = np.asarray(traj.pressure)[1:] + rng.normal(0.0, NOISE["pressure_Pa"], time.size)
    ex.write_csv(path, time, {"robot_length_m": length, "pressure_Pa": pressure, "catheter_length_m": catheter})
    meta = {
        "drive": "forward",
        "seed": SEED,
        "truth": TRUTH,
        "noise_sd": NOISE,
        "inputs": "published pulse 0/150 kPa, period 1.3 s, width 90 %, delay 0.26 s; catheter 0.004 + 0.004 t m",
        "solver": {"rtol": 1e-7, "atol": 1e-7},
    }
    path.with_suffix(".json").write_text(json.dumps(meta, indent=2) + "\n")
    return path


if __name__ == "__main__":
    print(make_forward())
