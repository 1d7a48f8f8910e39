"""Synthetic experiments with a hidden physical effect: test data for effect discovery.

`make_experiment` simulates the robot with one hidden effect (a catalogue effect from
`growjax.model.effects.CATALOGUE`, an effect from outside the catalogue (`OUTSIDE`), or none)
with the **reference** configuration (`growjax.simulation.reference`; never the fast one, so a
discovery run on the fast configuration is not fitted to its own solver), adds seeded Gaussian
noise to the length (and the pressure), and returns a `SyntheticExperiment`: a
`growjax.data.experiment.Experiment` in the CSV format of `growjax.data.experiment`
(``time_s``, ``robot_length_m``, ``pressure_Pa``, ``catheter_length_m`` and, where needed,
``pressure_demand_Pa`` or ``desired_length_m``), with the truth in ``metadata`` for a JSON sidecar
(`SyntheticExperiment.write`).

The noise-free reference solve is the expensive part (a 10 s run is tens of seconds, plus about a
minute to compile on first use in a process): it is cached in memory per (effect, magnitude, drive,
inputs, t_end, dt, rtol, base), so many noise seeds reuse one solve (`noise_free`,
`clear_cache`).

Inputs (``inputs=``):

* ``"public"``: the catheter length of the public MAMMOBOT experiment
  (`growjax.data.experiment.shared_experiment_dir`, ``../shared/data/mammobot``) and, as the
  published model does, the published 0/150 kPa pulse (the demand was not recorded); the inverse
  drive takes the measured length as the desired one. **Where that folder is absent (CI)** the
  shipped ``growjax/data/datasets/synthetic_forward.csv`` is used instead (catheter 0.004 + 0.004·t m, published
  pulse, 0.01–10 s), and if that too is missing, the published pulse with the same catheter ramp.
  ``metadata["inputs"]`` says which was used.
* ``"synthetic"``: always the shipped ``growjax/data/datasets/synthetic_forward.csv`` inputs (same fallback).
* a `growjax.Inputs`: used as given, sampled every ``dt`` for the CSV columns.

Magnitudes: `moderate_magnitude` gives an effect's class attribute ``moderate``, a value inside its physical range
that moves the length trace by clearly more than the 0.2 mm measurement noise within 3 s under the published pulse
(the values the effect tests use, ``tests/test_effects.py``); an effect added with `growjax.model.effects.register`
brings its own.

The modules: the effects outside the catalogue (``outside``), the hidden effect (``hidden``), the inputs
(``inputs``), the cached noise-free solve (``solve``) and the experiment with its noise and truth (``experiment``).

Example::

    from growjax.data import synthetic
    exp = synthetic.make_experiment("active_channel_force", None, seed=1)   # moderate magnitude
    exp.write("out/acf.csv")                                                 # CSV + out/acf.json
"""

from .experiment import (
    MEASURED_OUTPUTS,
    NOISE_LENGTH_M,
    NOISE_PRESSURE_PA,
    SyntheticExperiment,
    base_overrides,
    make_experiment,
    noisy,
    read_truth,
)
from .hidden import (
    effect_class,
    hidden_effect_parameters,
    known_effects,
    magnitude_field,
    make_effect,
    moderate_magnitude,
)
from .inputs import SHIPPED_INPUTS, resolve_inputs, shipped_inputs_path
from .outside import OUTSIDE, HoseCompliance, OscillatingForce
from .solve import CACHE_SIZE, clear_cache, noise_free

__all__ = [
    "MEASURED_OUTPUTS",
    "base_overrides",
    "noisy",
    "CACHE_SIZE",
    "NOISE_LENGTH_M",
    "NOISE_PRESSURE_PA",
    "OUTSIDE",
    "SHIPPED_INPUTS",
    "HoseCompliance",
    "OscillatingForce",
    "SyntheticExperiment",
    "clear_cache",
    "effect_class",
    "hidden_effect_parameters",
    "known_effects",
    "magnitude_field",
    "make_effect",
    "make_experiment",
    "moderate_magnitude",
    "noise_free",
    "read_truth",
    "resolve_inputs",
    "shipped_inputs_path",
]
