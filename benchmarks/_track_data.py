"""The records the tracking benchmark scores the filters on, made once per run (or read back from its folder).

Every record is made by the **reference** configuration (the filters run the fast one) on the shipped synthetic
inputs (catheter 0.004 + 0.004 t m, the published 0/150 kPa pulse), with Gaussian noise of 0.5 kPa on the pressure,
5 µm on the syringe displacement, 0.2 mm on the length and 1e-9 m³/s on the inlet flow:

* ``rig<i>``: a rig drawn from the default tolerance budget (``growjax.calibration.tolerance.rig_draws``), 10 s;
* ``drift<i>``: a rig drawn likewise whose Y rises by 10 % over 60 s (held over 0.25 s segments), on a robot whose
  stroke is 0.5 m (the published pulse grows a rig of the budget by up to 0.3 m in a minute; the rig's own stroke is
  0.08 m) and a catheter held at 0.06 m after 14 s.

* ``leak<i>``, ``tip<i>``: a rig drawn likewise, 10 s, a leak of 2e-13 m³/(s·Pa) opening or a tip load of 0.3 N
  (``active_channel_force``) appearing at a time drawn in 2–8 s (the sidecar's ``"switch"``);
* ``clean<i>``: a rig drawn likewise, 60 s on the drift records' robot and inputs, nothing changing.

Each record's JSON sidecar holds its rig (``"rig"``) and its noise-free length (``"noise_free_length_m"``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

import growjax as gj
from growjax.calibration import tolerance as tl
from growjax.data import experiment as ex
from growjax.data import synthetic as sy
from growjax.data.drifting import drifting_experiment, switching_experiment
from growjax.model import effects as fx

NOISE = {"robot_length_m": 2e-4, "pressure_Pa": 500.0, "syringe_displacement_m": 5e-6, "robot_flow_m3_s": 1e-9}
SEED = 20261201
DRIFT = 0.10  # Y's relative change over the drift record
DRIFT_STROKE_M = 0.5
CATHETER_HOLD_M = 0.06


def rigs(n: int, seed: int = SEED) -> list[dict]:
    """``n`` rigs from the default tolerance budget: {qualified name: value} each."""
    base = gj.reference("forward")
    draws = tl.rig_draws(n, base, tl.default_budget(base), seed=seed)
    return [{k: float(v[i]) for k, v in draws.items()} for i in range(n)]


def _write(exp, path: Path, extra: dict) -> Path:
    exp.write(path)
    path.with_suffix(".json").write_text(json.dumps({**exp.metadata, **extra}, indent=2) + "\n")
    return path


def make_rig_records(folder: Path, n: int, t_end: float, log=print) -> list[Path]:
    """The ``rig<i>`` records in ``folder`` (those already there are kept)."""
    paths = []
    for i, rig in enumerate(rigs(n)):
        path = folder / f"rig{i}.csv"
        if not path.exists():
            clock = time.perf_counter()
            base = gj.replace(gj.reference("forward"), **rig)
            exp = sy.make_experiment(
                None,
                seed=SEED + i,
                noise_m=NOISE["robot_length_m"],
                noise_pressure_Pa=NOISE["pressure_Pa"],
                noise_syringe_m=NOISE["syringe_displacement_m"],
                noise_flow_m3_s=NOISE["robot_flow_m3_s"],
                inputs="synthetic",
                t_end=t_end,
                base=base,
                superset=False,
            )
            clean = sy.noise_free(None, inputs="synthetic", t_end=t_end, base=base, superset=False)
            _write(exp, path, {"rig": rig, "noise_free_length_m": clean["length"].tolist()})
            log(f"made {path.name} ({time.perf_counter() - clock:.0f} s)")
        paths.append(path)
    return paths


def drift_inputs(t_end: float):
    """The drift records' inputs: the published pulse, the shipped catheter ramp held at 0.06 m."""
    time_ = np.round(np.arange(1, round(t_end / 0.01) + 1) * 0.01, 10)
    catheter = np.minimum(0.004 + 0.004 * time_, CATHETER_HOLD_M)
    return gj.Inputs(catheter_length=gj.Sampled(time_, catheter), pressure_demand=gj.published_pulse())


def drift_base(rig: dict):
    """A drift record's rig: ``rig`` on the reference parameters, the robot's stroke (and stop) at `DRIFT_STROKE_M`."""
    return gj.replace(
        gj.reference("forward"), **rig, **{"robot.stroke": DRIFT_STROKE_M, "robot.hard_stop_bound": DRIFT_STROKE_M}
    )


def make_drift_records(folder: Path, n: int, t_end: float, log=print) -> list[Path]:
    """The ``drift<i>`` records in ``folder`` (those already there are kept)."""
    paths = []
    for i, rig in enumerate(rigs(n, seed=SEED + 1)):
        path = folder / f"drift{i}.csv"
        if not path.exists():
            clock = time.perf_counter()
            exp = drifting_experiment(
                "Y",
                DRIFT,
                seed=SEED + 100 + i,
                t_end=t_end,
                base=drift_base(rig),
                inputs=drift_inputs(t_end),
                noise=NOISE,
            )
            _write(exp, path, {"rig": rig})
            log(f"made {path.name} ({time.perf_counter() - clock:.0f} s)")
        paths.append(path)
    return paths


CHANGES = {
    "leak": (fx.FluidLeak(), "fluid_leak.conductance", 2e-13),
    "tip": (fx.ActiveChannelForce(), "active_channel_force.force", 0.3),
}
CHANGE_WINDOW_S = (2.0, 8.0)


def make_change_records(folder: Path, kind: str, n: int, t_end: float, log=print) -> list[Path]:
    """The ``leak<i>`` or ``tip<i>`` records (``kind``) in ``folder`` (those already there are kept)."""
    effect, name, value = CHANGES[kind]
    offset = 1000 * (1 + list(CHANGES).index(kind))
    paths = []
    for i, rig in enumerate(rigs(n, seed=SEED + offset)):
        path = folder / f"{kind}{i}.csv"
        if not path.exists():
            clock = time.perf_counter()
            at = float(np.round(np.random.default_rng(SEED + offset + i).uniform(*CHANGE_WINDOW_S), 3))
            base = gj.with_effects(gj.replace(gj.reference("forward"), **rig), effect)
            exp = switching_experiment(
                {name: value}, at, seed=SEED + offset + 100 + i, t_end=t_end, base=base, noise=NOISE
            )
            _write(exp, path, {"rig": rig})
            log(f"made {path.name} ({time.perf_counter() - clock:.0f} s)")
        paths.append(path)
    return paths


def make_clean_records(folder: Path, n: int, t_end: float, log=print) -> list[Path]:
    """The ``clean<i>`` records in ``folder`` (those already there are kept)."""
    paths = []
    for i, rig in enumerate(rigs(n, seed=SEED + 3000)):
        path = folder / f"clean{i}.csv"
        if not path.exists():
            clock = time.perf_counter()
            exp = drifting_experiment(
                "Y",
                0.0,
                seed=SEED + 3100 + i,
                t_end=t_end,
                segment=t_end,
                base=drift_base(rig),
                inputs=drift_inputs(t_end),
                noise=NOISE,
            )
            _write(exp, path, {"rig": rig})
            log(f"made {path.name} ({time.perf_counter() - clock:.0f} s)")
        paths.append(path)
    return paths


def read_record(path: Path) -> tuple[ex.Experiment, dict]:
    """(the record, its sidecar)."""
    return ex.read(path), json.loads(path.with_suffix(".json").read_text())
