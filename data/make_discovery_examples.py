"""Make the small example experiments with a hidden effect in src/growjax/data/datasets/discovery/ (and the effect tests' reference traces).

Run from the repository root: ``python data/make_discovery_examples.py`` (a few minutes: the reference
configuration compiles once, then each 10 s solve takes tens of seconds). Deterministic.

src/growjax/data/datasets/discovery/<name>.csv + <name>.json — 0.01–10 s at 100 Hz, forward drive, made by
:func:`growjax.data.synthetic.make_experiment` (reference configuration, rtol 1e-6) on synthetic inputs
(catheter 0.004 + 0.004 t m and the published 0/150 kPa pulse; no public data are copied),
Gaussian noise σ = 0.2 mm on the length and 500 Pa on the pressure. The JSON sidecar holds the truth
(effect, parameter, magnitude), the noise, the seed and the inputs:

* ``clean``: no effect;
* ``active_channel_force``: F_ac = 0.01 N pulling the robot back;
* ``retraction_folding``: f = 0.3 of each retraction folds inside;
* ``outside_oscillating_force``: a zero-mean force 0.02 N·sin(2πt/2.1 s), outside the catalogue;
* ``outside_hose_compliance``: a hose compliance growing with pressure, outside the catalogue.

src/growjax/data/datasets/discovery/reference/effect_lengths.csv + .json — noise-free robot length (m), 0.01–3 s, made by
the *reference* configuration (rtol 1e-7) with each catalogue effect at its moderate magnitude
(:func:`growjax.data.synthetic.moderate_magnitude`) and with none (column ``none``), on the shipped
synthetic inputs (catheter 0.004 + 0.004 t m, published pulse), so that tests/test_effects.py checks the
fast configuration against the reference with each effect switched on without paying for the
reference solver. Rewrite it when an effect, its moderate magnitude or either configuration changes.
"""

from __future__ import annotations

import json
import sys
import time as clock
from pathlib import Path

import numpy as np

from growjax.data import experiment as ex
from growjax.data import synthetic as sy
from growjax.model.effects import CATALOGUE

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "src" / "growjax" / "data" / "datasets" / "discovery"  # package resources
REFERENCE = OUT / "reference" / "effect_lengths.csv"
SEED = 20261122
T_END = 10.0
NOISE_M = 2e-4

# name: (effect, magnitude (None: moderate), seed offset)
EXAMPLES = {
    "clean": (None, None, 0),
    "active_channel_force": ("active_channel_force", None, 1),
    "retraction_folding": ("retraction_folding", None, 2),
    "outside_oscillating_force": ("oscillating_force", None, 3),
    "outside_hose_compliance": ("hose_compliance", None, 4),
}

REFERENCE_T_END = 3.0
REFERENCE_RTOL = 1e-7


def make_examples(out: Path = OUT, names=None) -> list[Path]:
    paths = []
    for name, (effect, magnitude, k) in EXAMPLES.items():
        if names and name not in names:
            continue
        start = clock.time()
        exp = sy.make_experiment(
            effect, magnitude, seed=SEED + k, noise_m=NOISE_M, drive="forward", inputs="synthetic", t_end=T_END
        )
        meta = dict(exp.metadata, example=name)
        path = sy.SyntheticExperiment(exp.time, exp.series, exp.source, meta).write(out / f"{name}.csv")
        print(f"{path}  {path.stat().st_size / 1e3:.0f} kB  ({clock.time() - start:.0f} s)", flush=True)
        paths.append(path)
    return paths


def make_reference(path: Path = REFERENCE) -> Path:
    columns, cases, description = {}, {}, ""
    time = None
    for name in ["none", *CATALOGUE]:
        start = clock.time()
        effect = None if name == "none" else name
        clean = sy.noise_free(effect, None, inputs="synthetic", t_end=REFERENCE_T_END, rtol=REFERENCE_RTOL)
        time, description = clean["time"], clean["inputs"]
        columns[name] = clean["length"]
        if effect is not None:
            cases[name] = {"parameter": f"{name}.{sy.magnitude_field(name)}", "magnitude": clean["magnitude"]}
        print(f"reference {name}: final {columns[name][-1] * 1e3:.3f} mm ({clock.time() - start:.0f} s)", flush=True)
    ex.write_csv(path, time, columns)
    info = {
        "configuration": {
            "fidelity": "reference",
            "rtol": REFERENCE_RTOL,
            "atol": REFERENCE_RTOL,
            "superset": True,
            "drive": "forward",
        },
        "inputs": description,
        "t_end_s": REFERENCE_T_END,
        "cases": cases,
        "made_by": "data/make_discovery_examples.py (growjax.data.synthetic.noise_free)",
    }
    path.with_suffix(".json").write_text(json.dumps(info, indent=2) + "\n")
    return path


def read_reference(path: Path = REFERENCE):
    """(time s (T,), {case: length m (T,)}, metadata) of the shipped effect reference traces."""
    table = np.genfromtxt(path, delimiter=",", names=True)
    names = [n for n in table.dtype.names if n != "time_s"]
    return (
        np.asarray(table["time_s"]),
        {n: np.asarray(table[n]) for n in names},
        json.loads(path.with_suffix(".json").read_text()),
    )


if __name__ == "__main__":
    which = set(sys.argv[1:])
    if not which or "reference" in which:
        print(make_reference())
    if not which or which - {"reference"}:
        make_examples(names=which - {"reference"} or None)
