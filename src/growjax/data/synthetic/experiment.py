"""A synthetic experiment: the noise-free solve with seeded noise, its columns and its truth."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

import growjax as gj
from growjax.data import experiment as ex
from growjax.model import effects as fx
from growjax.model.effects import Effect

from .hidden import magnitude_field
from .solve import noise_free

__all__ = [
    "MEASURED_OUTPUTS",
    "NOISE_LENGTH_M",
    "NOISE_PRESSURE_PA",
    "SyntheticExperiment",
    "base_overrides",
    "make_experiment",
    "noisy",
    "read_truth",
]

NOISE_LENGTH_M = 2e-4
NOISE_PRESSURE_PA = 500.0


@dataclasses.dataclass(frozen=True)
class SyntheticExperiment(ex.Experiment):
    """An `growjax.data.experiment.Experiment` with its truth: ``metadata`` (JSON-serialisable dict).

    ``metadata`` holds ``effect`` (name or None), ``in_catalogue``, ``parameter`` (``effect.field``),
    ``magnitude`` (SI), ``unit``, ``effect_fields`` (all fields of the hidden effect), ``noise_sd``,
    ``seed``, ``drive``, ``t_end_s``, ``inputs`` (description), ``base_parameters`` (overrides of
    `growjax.reference`), ``solver`` and ``generator``.
    """

    metadata: dict = dataclasses.field(default_factory=dict)

    @property
    def truth(self) -> dict:
        """{"effect", "parameter", "magnitude"} of the hidden effect."""
        return {k: self.metadata.get(k) for k in ("effect", "parameter", "magnitude")}

    def write(self, path) -> Path:
        """Write the CSV to ``path`` and the metadata beside it (same name, ``.json``); returns the CSV path."""
        path = Path(path)
        ex.write_csv(path, self.time, self.series)
        path.with_suffix(".json").write_text(json.dumps(self.metadata, indent=2) + "\n")
        return path


def base_overrides(base, drive: str) -> dict:
    """The parameters of ``base`` that differ from ``growjax.reference(drive)``: {qualified name: value}."""
    if base is None:
        return {}
    ref = gj.as_dict(gj.reference(drive))
    mine = gj.as_dict(base)
    out = {k: v for k, v in mine.items() if k not in ref or ref[k] != v}
    if base.robot.growth_law != "reference":
        out["robot.growth_law"] = base.robot.growth_law
    return out


MEASURED_OUTPUTS = {
    "robot_length_m": "length",
    "pressure_Pa": "pressure",
    "syringe_displacement_m": "syringe_displacement",
    "robot_flow_m3_s": "robot_flow",
}  # a measured column: the output of a noise-free solve it reads


def noisy(clean: dict, noise: dict, rng) -> dict:
    """The measured columns {column: (T,)} of a noise-free solve ``clean`` (`noise_free`'s outputs), each plus
    Gaussian noise of sd ``noise[column]`` drawn from ``rng`` in the order of ``noise``."""
    return {
        c: clean[MEASURED_OUTPUTS[c]] + rng.normal(0.0, sd, clean[MEASURED_OUTPUTS[c]].size) for c, sd in noise.items()
    }


def make_experiment(
    effect: str | Effect | None = None,
    magnitude: float | None = None,
    *,
    seed: int,
    noise_m: float = NOISE_LENGTH_M,
    noise_pressure_Pa: float | None = NOISE_PRESSURE_PA,
    noise_syringe_m: float | None = None,
    noise_flow_m3_s: float | None = None,
    drive: str = "forward",
    inputs="public",
    t_end: float = 10.0,
    base=None,
    dt: float = 0.01,
    rtol: float = 1e-6,
    superset: bool = True,
) -> SyntheticExperiment:
    """A synthetic experiment with a hidden ``effect``, simulated by the reference configuration.

    Args:
        effect: a name from `growjax.model.effects.CATALOGUE` or `OUTSIDE`, an
            `growjax.Effect` instance (any fields; ``magnitude`` must then be None), or None (clean).
        magnitude: the effect's `magnitude_field` (SI); None gives `moderate_magnitude`.
        seed: seed of the noise (``numpy.random.default_rng``); length noise is drawn first, then pressure.
        noise_m: standard deviation of the Gaussian noise on the length, m (0.2 mm: the rig's).
        noise_pressure_Pa: standard deviation on the pressure, Pa; None leaves out the ``pressure_Pa``
            column (the public experiment has none).
        noise_syringe_m: standard deviation on the syringe displacement, m (a stepper's step count or an
            encoder: 5 µm); None (default) leaves out the ``syringe_displacement_m`` column.
        noise_flow_m3_s: standard deviation on the robot's inlet flow, m³/s; None (default) leaves out the
            ``robot_flow_m3_s`` column.
        drive: ``"forward"`` or ``"inverse"``.
        inputs: ``"public"``, ``"synthetic"`` or a `growjax.Inputs` (see the module docstring,
            including the fallback when the public experiment is absent).
        t_end: end of the experiment, s (samples every ``dt`` from dt to t_end).
        base: base parameters (default `growjax.reference` for the drive); effects already in
            them stay, and the hidden one is added (replacing one of the same name).
        rtol: tolerance of the reference solver (also its atol, on scaled states).
        superset: simulate in the model carrying every known effect at zero but the hidden one
            (`hidden_effect_parameters`): the same model, one compiled solver for all effects.

    Returns:
        `SyntheticExperiment`: columns ``robot_length_m`` (noisy), ``pressure_Pa`` (noisy, unless
        ``noise_pressure_Pa`` is None), the inputs ``catheter_length_m`` and, where the published pulse is
        not the demand, ``pressure_demand_Pa`` (forward) or ``desired_length_m`` (inverse), so that
        `growjax.data.experiment.to_inputs` of it gives back the inputs; ``metadata`` holds the truth.
    """
    clean = noise_free(
        effect, magnitude, drive=drive, inputs=inputs, t_end=t_end, base=base, dt=dt, rtol=rtol, superset=superset
    )
    time = clean["time"]
    noise = {"robot_length_m": noise_m, "pressure_Pa": noise_pressure_Pa, "syringe_displacement_m": noise_syringe_m}
    noise = {c: sd for c, sd in {**noise, "robot_flow_m3_s": noise_flow_m3_s}.items() if sd is not None}
    series = {**noisy(clean, noise, np.random.default_rng(seed)), **clean["columns"]}
    ex.validate_series(time, series, "synthetic experiment")
    instance, name = clean["effect"], clean["name"]
    meta = {
        "effect": name,
        "in_catalogue": None if name is None else name in fx.CATALOGUE,
        "parameter": None if name is None else f"{name}.{magnitude_field(instance)}",
        "magnitude": clean["magnitude"],
        "unit": None if name is None else instance.units.get(magnitude_field(instance), ""),
        "effect_fields": None
        if instance is None
        else {f.name: float(getattr(instance, f.name)) for f in dataclasses.fields(instance)},
        "description": None if instance is None else instance.description,
        "noise_sd": noise,
        "seed": int(seed),
        "drive": drive,
        "t_end_s": float(time[-1]),
        "inputs": clean["inputs"],
        "base_parameters": base_overrides(base, drive),
        "solver": {"fidelity": "reference", "rtol": rtol, "atol": rtol, "superset": superset},
        "generator": "growjax.data.synthetic.make_experiment",
    }
    label = f"synthetic: {name or 'clean'}" + ("" if name is None else f" {meta['parameter']}={clean['magnitude']:g}")
    return SyntheticExperiment(time, series, f"{label}, seed {seed}", metadata=meta)


def read_truth(csv_path) -> dict:
    """The metadata written beside a synthetic experiment's CSV (its ``.json``)."""
    return json.loads(Path(csv_path).with_suffix(".json").read_text())
