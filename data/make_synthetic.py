"""Make the small synthetic experiments shipped with the package (``src/growjax/data/datasets/``).

Run from the repository root: ``python data/make_synthetic.py``. Deterministic:
seed 20261121. Ground truth and noise are written beside each CSV as JSON.

synthetic_forward.csv — forward drive (published 0/150 kPa pulse, shipped PID),
reference parameters except Y = 9000 Pa, catheter length 4 mm + 4 mm/s·t,
0.01–10 s at 100 Hz; Gaussian noise σ = 0.2 mm on length, σ = 500 Pa on pressure.

reference_lengths.csv — noise-free robot length (m) at 0.01–10 s made by the *reference*
configuration (rtol 1e-7), for the tests and benchmarks that check the fast configuration against
it and its fits against data it did not make: five Y across the paper's box and 20 seeded
Latin-hypercube Y under the published pulse; other demands (pulse trains of other timing and
amplitude, a step and a ramp given as data); the Lockhart growth law; and a rig parameter held wrong (the lead
screw's friction 10 % low), for a discrepancy of the rig rather than of the model.
Cases and their parameters are listed in reference_lengths.json.

set/ — an experiment set: one robot (Y = 9000 Pa) on one rig whose toleranced parameters are off their nominal
values (drawn once from the default budget, recorded in set/truth.json), run under three pressure demands
(the published pulse train, a slower train and a 100 kPa train) given to the controller as sampled every 10 ms
(the CSV's demand column), made by the reference configuration; noise as above. set/set.toml is its manifest (the pressure sensor named
for the first experiment).

population/ — a population: eight membranes built alike (Y_i = 8 kPa·e^(0.1 η_i)) on one rig drawn from the
default budget, each under its own seeded pulse train (100–160 kPa), length only; new_robot.csv is a ninth of the
same population, held out. population/population.toml names each experiment's robot; truth in
population/truth.json.
"""

from __future__ import annotations

import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax.data import experiment as ex

SEED = 20261121
HERE = Path(__file__).resolve().parent
DATASETS = HERE.parent / "src" / "growjax" / "data" / "datasets"  # package resources
TRUTH = {"Y": 9000.0}
NOISE = {"robot_length_m": 2e-4, "pressure_Pa": 500.0}
POPULATION_MEDIAN, POPULATION_SPREAD = 8000.0, 0.1  # Pa, sd of ln Y


def make_forward(path: Path = DATASETS / "synthetic_forward.csv") -> Path:
    time = np.round(np.arange(1, 1001) * 0.01, 10)
    catheter = 0.004 + 0.004 * time
    params = gj.replace(gj.reference("forward"), **TRUTH)
    inputs = gj.Inputs(
        catheter_length=gj.Sampled(jnp.asarray(time), jnp.asarray(catheter)), pressure_demand=gj.published_pulse()
    )
    config = gj.Config(fidelity="reference", t1=float(time[-1]), rtol=1e-7, atol=1e-7)
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
        "solver": {"fidelity": "reference", "rtol": 1e-7, "atol": 1e-7},
    }
    path.with_suffix(".json").write_text(json.dumps(meta, indent=2) + "\n")
    return path


GRID_Y = (6000.0, 7920.0, 10000.0, 12000.0, 14000.0)
TRUTH_RTOL = 1e-7


def other_pulse_samples(time):
    """The second demand: 0/150 kPa, period 1.6 s, width 80 %, delay 0.3 s, as a sampled column (Pa)."""
    return np.asarray(gj.PulseTrain(150e3, 1.6, 0.8, 0.3)(jnp.asarray(time)))


# Demands beyond the published pulse train (Pa): analytic trains, and steps and ramps given as data.
DEMANDS = {
    "published": "PulseTrain 0/150 kPa, period 1.3 s, width 90 %, delay 0.26 s",
    "sampled": "0/150 kPa, period 1.6 s, width 80 %, delay 0.3 s, sampled every 10 ms",
    "pulse300": "PulseTrain 0/300 kPa, period 2.5 s, width 40 %, delay 0.5 s",
    "pulse50": "PulseTrain 0/50 kPa, period 1.0 s, width 60 %, delay 0.1 s",
    "step": "step 0 -> 120 kPa at 0.5 s, sampled every 10 ms",
    "ramp": "ramp 0 -> 250 kPa over 0-6 s, then 0 from 8 s, sampled every 10 ms",
}
LOCKHART = {"growth_law": "lockhart", "Y": 5068.0, "phi_L": 2.1e-3, "n_L": 0.253}


def demand(name: str, grid):
    """The named demand (see DEMANDS) as a signal; sampled ones on ``grid`` (s)."""
    if name == "published":
        return gj.published_pulse()
    if name == "pulse300":
        return gj.PulseTrain(300e3, 2.5, 0.4, 0.5)
    if name == "pulse50":
        return gj.PulseTrain(50e3, 1.0, 0.6, 0.1)
    if name == "sampled":
        values = other_pulse_samples(grid)
    elif name == "step":
        values = np.where(grid >= 0.5, 120e3, 0.0)
    elif name == "ramp":
        values = np.where(grid < 8.0, 250e3 * np.minimum(grid / 6.0, 1.0), 0.0)
    else:
        raise ValueError(f"unknown demand {name!r}")
    return gj.Sampled(jnp.asarray(grid), jnp.asarray(values))


def reference_cases() -> dict:
    """{case name: (parameter overrides, demand name)} of the reference-made length traces."""
    from scipy.stats import qmc

    cases = {f"published_Y{y:.0f}": ({"Y": y}, "published") for y in GRID_Y}
    cases.update({f"sampled_Y{y:.0f}": ({"Y": y}, "sampled") for y in (6000.0, 10000.0)})
    cases.update(
        {
            "pulse50_Y6000": ({"Y": 6000.0}, "pulse50"),
            "step_Y8000": ({"Y": 8000.0}, "step"),
            "ramp_Y12000": ({"Y": 12000.0}, "ramp"),
        }
    )
    cases.update({"lockhart_published": (LOCKHART, "published"), "lockhart_sampled": (LOCKHART, "sampled")})
    draws = 5e3 + 10e3 * qmc.LatinHypercube(d=1, seed=np.random.default_rng(SEED)).random(20)[:, 0]
    cases.update({f"published_lhs{k:02d}": ({"Y": float(np.round(y, 1))}, "published") for k, y in enumerate(draws)})
    cases["pulse300_Y10000"] = ({"Y": 10000.0}, "pulse300")
    # a rig parameter held wrong: the lead screw's viscous friction 10 % below the published 0.1 N·s/m
    cases["published_Y9000_screw_friction_low"] = ({"Y": 9000.0, "pump.screw_viscous_friction": 0.09}, "published")
    return cases


def case_parameters(overrides: dict):
    """Forward-drive parameters of a reference case."""
    overrides = dict(overrides)
    law = overrides.pop("growth_law", "reference")
    return gj.replace(gj.reference("forward", growth_law=law), **overrides)


def reference_inputs(demand_name: str):
    """Inputs of a reference case: catheter 0.004 + 0.004 t m and the named demand."""
    grid = np.round(np.arange(0, 1001) * 0.01, 10)
    catheter = gj.Sampled(jnp.asarray(grid), jnp.asarray(0.004 + 0.004 * grid))
    return gj.Inputs(catheter_length=catheter, pressure_demand=demand(demand_name, grid))


def make_reference_lengths(path: Path = DATASETS / "reference_lengths.csv") -> Path:
    """Simulate every reference case; the files are rewritten after each case, and a case the reference
    solver cannot finish is listed under "failed" rather than written."""
    time = np.round(np.arange(1, 1001) * 0.01, 10)
    config = gj.Config(fidelity="reference", t1=float(time[-1]), rtol=TRUTH_RTOL)
    ts = np.concatenate([[config.t0], time])
    columns, meta, failed = {}, {}, {}
    for name, (overrides, demand_name) in reference_cases().items():
        traj = gj.simulate(case_parameters(overrides), reference_inputs(demand_name), config, ts=ts)
        if int(traj.status) != gj.OK:
            failed[name] = {"status": gj.status_name(traj.status), "t_final_s": float(traj.t_final)}
            print(name, "FAILED", failed[name], flush=True)
        else:
            columns[name] = np.asarray(traj.length)[1:]
            meta[name] = {"parameters": overrides, "demand": demand_name}
            print(name, f"{float(columns[name][-1]) * 1e3:.3f} mm", flush=True)
        ex.write_csv(path, time, columns)
        info = {
            "configuration": {"fidelity": "reference", "rtol": TRUTH_RTOL},
            "seed": SEED,
            "catheter_length_m": "0.004 + 0.004 t",
            "cases": meta,
            "failed": failed,
            "demands": DEMANDS,
        }
        path.with_suffix(".json").write_text(json.dumps(info, indent=2) + "\n")
    return path


def read_reference_lengths(path: Path = DATASETS / "reference_lengths.csv"):
    """(time s (T,), {case: length m (T,)}, {case: {"parameters", "demand"}}) of the shipped reference traces."""
    table = np.genfromtxt(path, delimiter=",", names=True)
    names = [n for n in table.dtype.names if n != "time_s"]
    cases = json.loads(path.with_suffix(".json").read_text())["cases"]
    return np.asarray(table["time_s"]), {n: np.asarray(table[n]) for n in names}, cases


SET_DEMANDS = {
    "pulse_published": gj.published_pulse(),
    "pulse_slow": gj.PulseTrain(150e3, 1.6, 0.8, 0.3),
    "pulse_100kPa": gj.PulseTrain(100e3, 2.0, 0.6, 0.2),
}


def make_set(folder: Path = DATASETS / "set") -> Path:
    """The experiment set: three demands on one robot and one rig drawn from the default tolerance budget."""
    from growjax.calibration import tolerance as tl

    folder.mkdir(parents=True, exist_ok=True)
    time = np.round(np.arange(1, 1001) * 0.01, 10)
    catheter = 0.004 + 0.004 * time
    base = gj.replace(gj.reference("forward"), **TRUTH)
    rng = np.random.default_rng(SEED + 1)
    offsets = {k: float(rng.normal(0.0, u)) for k, u in tl.default_budget(base).items()}
    rig = gj.replace(base, **{k: gj.get(base, k) * np.exp(b) for k, b in offsets.items()})
    config = gj.Config(fidelity="reference", t1=float(time[-1]), rtol=TRUTH_RTOL, atol=TRUTH_RTOL)
    ts = np.concatenate([[config.t0], time])
    for name, demand_signal in SET_DEMANDS.items():
        demand_column = np.asarray(demand_signal(jnp.asarray(time)))
        # the rig's controller reads the demand as recorded: sampled every 10 ms, as the CSV gives it back
        inputs = gj.Inputs(
            catheter_length=gj.Sampled(jnp.asarray(time), jnp.asarray(catheter)),
            pressure_demand=gj.Sampled(jnp.asarray(time), jnp.asarray(demand_column)),
        )
        traj = gj.simulate(rig, inputs, config, ts=ts)
        assert int(traj.status) == gj.OK, (name, gj.status_name(traj.status))
        length = np.asarray(traj.length)[1:] + rng.normal(0.0, NOISE["robot_length_m"], time.size)
        pressure = np.asarray(traj.pressure)[1:] + rng.normal(0.0, NOISE["pressure_Pa"], time.size)
        ex.write_csv(
            folder / f"{name}.csv",
            time,
            {
                "robot_length_m": length,
                "pressure_Pa": pressure,
                "catheter_length_m": catheter,
                "pressure_demand_Pa": demand_column,
            },
        )
        print(name, f"{float(length[-1]) * 1e3:.3f} mm", flush=True)
    manifest = [
        "# One robot, one rig, three pressure demands (made by data/make_synthetic.py).",
        "[defaults]",
        'drive = "forward"',
        'robot = "membrane-1"',
        'rig = "bench"',
        "",
    ]
    for k, name in enumerate(SET_DEMANDS):
        manifest += ["[[experiment]]", f'file = "{name}.csv"']
        if k == 0:
            manifest.append('sensors = ["length", "pressure"]')
        manifest.append("")
    (folder / "set.toml").write_text("\n".join(manifest))
    meta = {
        "seed": SEED + 1,
        "truth": TRUTH,
        "rig_offsets_ln": offsets,
        "noise_sd": NOISE,
        "demands": {k: repr(v) for k, v in SET_DEMANDS.items()},
        "catheter_length_m": "0.004 + 0.004 t",
        "solver": {"fidelity": "reference", "rtol": TRUTH_RTOL},
    }
    (folder / "truth.json").write_text(json.dumps(meta, indent=2) + "\n")
    return folder


def make_population(folder: Path = DATASETS / "population", robots: int = 8) -> Path:
    """A population: ``robots`` membranes built alike (Y_i = 8 kPa·e^(0.1 η_i)) on one rig drawn from the default
    tolerance budget, each under its own pulse train, plus one more robot of the same population held out
    (new_robot.csv) to check a new robot's predictive band against."""
    from growjax.calibration import tolerance as tl

    folder.mkdir(parents=True, exist_ok=True)
    time = np.round(np.arange(1, 1001) * 0.01, 10)
    catheter = 0.004 + 0.004 * time
    base = gj.reference("forward")
    rng = np.random.default_rng(SEED + 2)
    offsets = {k: float(rng.normal(0.0, u)) for k, u in tl.default_budget(base).items()}
    rig = gj.replace(base, **{k: gj.get(base, k) * np.exp(b) for k, b in offsets.items()})
    ys = POPULATION_MEDIAN * np.exp(POPULATION_SPREAD * rng.standard_normal(robots + 1))
    config = gj.Config(fidelity="reference", t1=float(time[-1]), rtol=TRUTH_RTOL, atol=TRUTH_RTOL)
    ts = np.concatenate([[config.t0], time])
    names = [f"robot_{i + 1}" for i in range(robots)] + ["new_robot"]
    trains = {}
    for name, y in zip(names, ys):
        train = gj.PulseTrain(
            float(rng.uniform(100e3, 160e3)),
            float(rng.uniform(1.2, 2.2)),
            float(rng.uniform(0.5, 0.8)),
            float(rng.uniform(0.1, 0.4)),
        )
        demand_column = np.asarray(train(jnp.asarray(time)))
        inputs = gj.Inputs(
            catheter_length=gj.Sampled(jnp.asarray(time), jnp.asarray(catheter)),
            pressure_demand=gj.Sampled(jnp.asarray(time), jnp.asarray(demand_column)),
        )
        traj = gj.simulate(gj.replace(rig, Y=float(y)), inputs, config, ts=ts)
        assert int(traj.status) == gj.OK, (name, gj.status_name(traj.status))
        length = np.asarray(traj.length)[1:] + rng.normal(0.0, NOISE["robot_length_m"], time.size)
        ex.write_csv(
            folder / f"{name}.csv",
            time,
            {"robot_length_m": length, "catheter_length_m": catheter, "pressure_demand_Pa": demand_column},
        )
        trains[name] = repr(train)
        print(name, f"Y {y:.0f} Pa, {float(length[-1]) * 1e3:.3f} mm", flush=True)
    manifest = [
        f"# {robots} robots built alike on one rig, one pulse train each (made by data/make_synthetic.py).",
        "[defaults]",
        'drive = "forward"',
        'rig = "bench"',
        "",
    ]
    for name in names[:-1]:
        manifest += ["[[experiment]]", f'file = "{name}.csv"', f'robot = "{name}"', ""]
    (folder / "population.toml").write_text("\n".join(manifest))
    meta = {
        "seed": SEED + 2,
        "truth": {"Y_median": POPULATION_MEDIAN, "Y_sd_ln": POPULATION_SPREAD, "Y": dict(zip(names, map(float, ys)))},
        "rig_offsets_ln": offsets,
        "noise_sd": {"robot_length_m": NOISE["robot_length_m"]},
        "demands": trains,
        "catheter_length_m": "0.004 + 0.004 t",
        "solver": {"fidelity": "reference", "rtol": TRUTH_RTOL},
    }
    (folder / "truth.json").write_text(json.dumps(meta, indent=2) + "\n")
    return folder


if __name__ == "__main__":
    import sys

    wanted = sys.argv[1:] or ["forward", "reference", "set", "population"]
    if "forward" in wanted:
        print(make_forward())
    if "reference" in wanted:
        print(make_reference_lengths())
    if "set" in wanted:
        print(make_set())
    if "population" in wanted:
        print(make_population())
