"""Make the small reference-made records the tracking tests read, in src/growjax/data/datasets/track/.

Run from the repository root: ``python data/make_track.py`` (several minutes: the reference configuration compiles
once for whole runs and once for runs stepped segment by segment, then each solve takes tens of seconds).
Deterministic.

Every record: 0.01–3 s at 100 Hz, forward drive, made by the *reference* configuration (rtol 1e-6; the filter
runs the fast one) on the shipped synthetic inputs (catheter 0.004 + 0.004 t m and the published 0/150 kPa
pulse; no public data are copied), with Gaussian noise of 0.2 mm on the length, 500 Pa on the pressure, 5 µm on
the syringe displacement and 1e-9 m³/s on the inlet flow. The JSON sidecar holds the rig (under ``"rig"``, so
that no command takes it as the parameters), the noise-free length (``noise_free_length_m``), the noise and the
seed:

* ``rig0`` … ``rig2``: rigs drawn from the default tolerance budget (:mod:`growjax.calibration.tolerance`);
* ``drift``: the nominal rig with Y rising by 10 % over the 3 s (held over 0.25 s segments);
* ``leak``, ``tip``: 3 s on a drawn rig, a leak opening (conductance 2e-13 m³/(s·Pa)) or a tip load (0.3 N of
  ``active_channel_force``) appearing at a time drawn in 1.2–2.4 s (the sidecar's ``"switch"``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import growjax as gj
from growjax.calibration import tolerance as tl
from growjax.data import synthetic as sy
from growjax.data.drifting import drifting_experiment, switching_experiment
from growjax.model import effects as fx

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "src" / "growjax" / "data" / "datasets" / "track"  # package resources
SEED = 20261201
T_END = 3.0
RIGS = 3
NOISE = {"robot_length_m": 2e-4, "pressure_Pa": 500.0, "syringe_displacement_m": 5e-6, "robot_flow_m3_s": 1e-9}


def rig_values(n: int, seed: int) -> list[dict]:
    """``n`` rigs drawn from the default tolerance budget: {qualified name: value} each (seeded)."""
    base = gj.reference("forward")
    draws = tl.rig_draws(n, base, tl.default_budget(base), seed=seed)
    return [{k: float(v[i]) for k, v in draws.items()} for i in range(n)]


def write(exp: sy.SyntheticExperiment, name: str, extra: dict) -> Path:
    path = exp.write(OUT / f"{name}.csv")
    meta = {**exp.metadata, **extra}
    path.with_suffix(".json").write_text(json.dumps(meta, indent=2) + "\n")
    return path


def make_rigs() -> list[Path]:
    paths = []
    for i, rig in enumerate(rig_values(RIGS, SEED)):
        base = gj.replace(gj.reference("forward"), **rig)
        exp = sy.make_experiment(
            None,
            seed=SEED + i,
            noise_m=NOISE["robot_length_m"],
            noise_pressure_Pa=NOISE["pressure_Pa"],
            noise_syringe_m=NOISE["syringe_displacement_m"],
            noise_flow_m3_s=NOISE["robot_flow_m3_s"],
            inputs="synthetic",
            t_end=T_END,
            base=base,
            superset=False,
        )
        clean = sy.noise_free(None, inputs="synthetic", t_end=T_END, base=base, superset=False)
        paths.append(write(exp, f"rig{i}", {"rig": rig, "noise_free_length_m": clean["length"].tolist()}))
        print(paths[-1], flush=True)
    return paths


def make_drift() -> Path:
    exp = drifting_experiment("Y", 0.1, seed=SEED + 10, t_end=T_END, noise=NOISE, inputs="synthetic")
    path = write(exp, "drift", {"rig": {}})
    print(path, flush=True)
    return path


CHANGES = {
    "leak": (fx.FluidLeak(), {"fluid_leak.conductance": 2e-13}),
    "tip": (fx.ActiveChannelForce(), {"active_channel_force.force": 0.3}),
}
CHANGE_T_END = T_END


def make_changes() -> list[Path]:
    paths = []
    for i, (name, (effect, values)) in enumerate(CHANGES.items()):
        rig = rig_values(1, SEED + 20 + i)[0]
        base = gj.with_effects(gj.replace(gj.reference("forward"), **rig), effect)
        at = float(np.round(np.random.default_rng(SEED + 30 + i).uniform(1.2, 2.4), 3))
        exp = switching_experiment(values, at, seed=SEED + 40 + i, t_end=CHANGE_T_END, base=base, noise=NOISE)
        paths.append(write(exp, name, {"rig": rig}))
        print(paths[-1], flush=True)
    return paths


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    which = set(sys.argv[1:]) or {"rigs", "drift", "changes"}
    if "rigs" in which:
        make_rigs()
    if "drift" in which:
        make_drift()
    if "changes" in which:
        make_changes()
