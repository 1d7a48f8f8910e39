"""Make the experiment set with a hidden effect in src/growjax/data/datasets/discovery_set/.

Run from the repository root: ``python data/make_discovery_set.py`` (about two minutes: the reference
configuration compiles once). Deterministic.

One robot on one rig at its nominal values, three pressure demands (those of the shipped set, ``set/``), each
0.01–3 s at 100 Hz, forward drive, made by :func:`growjax.data.synthetic.make_experiment` (reference configuration,
rtol 1e-6) with the same hidden effect, retraction folding of a small fraction of each retraction, too small for
one experiment to name it against the whole catalogue and large enough for the three together. Gaussian noise
σ = 0.2 mm on the length, 500 Pa on the pressure (recorded, not named a sensor in the manifest). ``set.toml`` is
the manifest; each CSV's JSON sidecar holds the truth.
"""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax.data import synthetic as sy

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "src" / "growjax" / "data" / "datasets" / "discovery_set"  # package resources
SEED = 20261126
T_END = 3.0
EFFECT = "retraction_folding"
MAGNITUDE = 0.01
DEMANDS = {
    "pulse_published": gj.published_pulse(),
    "pulse_slow": gj.PulseTrain(150e3, 1.6, 0.8, 0.3),
    "pulse_100kPa": gj.PulseTrain(100e3, 2.0, 0.6, 0.2),
}


def inputs_of(demand) -> gj.Inputs:
    """The rig's inputs: the catheter 0.004 + 0.004 t m and ``demand`` sampled every 10 ms (as the CSV gives it)."""
    time = np.round(np.arange(1, int(round(T_END * 100)) + 1) * 0.01, 10)
    return gj.Inputs(
        catheter_length=gj.Sampled(jnp.asarray(time), jnp.asarray(0.004 + 0.004 * time)),
        pressure_demand=gj.Sampled(jnp.asarray(time), demand(jnp.asarray(time))),
    )


def experiments(effect=EFFECT, magnitude=MAGNITUDE, seed=SEED) -> dict:
    """{name: SyntheticExperiment} of the three demands with ``effect`` hidden (None: clean)."""
    return {
        name: sy.make_experiment(
            effect, magnitude if effect else None, seed=seed + k, inputs=inputs_of(demand), t_end=T_END
        )
        for k, (name, demand) in enumerate(DEMANDS.items())
    }


def make_set(out: Path = OUT) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    for name, exp in experiments().items():
        exp.write(out / f"{name}.csv")
        print(out / f"{name}.csv", exp.truth, flush=True)
    manifest = [
        f"# One robot, one rig, three pressure demands; {EFFECT} {MAGNITUDE:g} hidden "
        "(made by data/make_discovery_set.py).",
        "[defaults]",
        'drive = "forward"',
        'robot = "membrane-1"',
        'rig = "bench"',
        "",
    ]
    for name in DEMANDS:
        manifest += ["[[experiment]]", f'file = "{name}.csv"', ""]
    (out / "set.toml").write_text("\n".join(manifest))
    return out


if __name__ == "__main__":
    print(make_set())
