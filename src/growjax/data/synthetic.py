"""Synthetic experiments with a hidden physical effect: test data for effect discovery.

:func:`make_experiment` simulates the robot with one hidden effect (a catalogue effect from
:data:`growjax.model.effects.CATALOGUE`, an effect from outside the catalogue (:data:`OUTSIDE`), or none)
with the **reference** configuration (:mod:`growjax.simulation.reference`; never the fast one, so a
discovery run on the fast configuration is not fitted to its own solver), adds seeded Gaussian
noise to the length (and the pressure), and returns a :class:`SyntheticExperiment`: a
:class:`growjax.data.experiment.Experiment` in the CSV format of :mod:`growjax.data.experiment`
(``time_s``, ``robot_length_m``, ``pressure_Pa``, ``catheter_length_m``, where asked the pump's own
``syringe_displacement_m`` and ``robot_flow_m3_s``, and, where needed, ``pressure_demand_Pa`` or
``desired_length_m``), with the truth in ``metadata`` for a JSON sidecar
(:meth:`SyntheticExperiment.write`).

The noise-free reference solve is the expensive part (a 10 s run is tens of seconds, plus about a
minute to compile on first use in a process): it is cached in memory per (effect, magnitude, drive,
inputs, t_end, dt, rtol, base), so many noise seeds reuse one solve (:func:`noise_free`,
:func:`clear_cache`).

Inputs (``inputs=``):

* ``"public"``: the catheter length of the public MAMMOBOT experiment
  (:func:`growjax.data.experiment.shared_experiment_dir`, ``../shared/data/mammobot``) and, as the
  published model does, the published 0/150 kPa pulse (the demand was not recorded); the inverse
  drive takes the measured length as the desired one. **Where that folder is absent (CI)** the
  shipped ``growjax/data/datasets/synthetic_forward.csv`` is used instead (catheter 0.004 + 0.004·t m, published
  pulse, 0.01–10 s), and if that too is missing, the published pulse with the same catheter ramp.
  ``metadata["inputs"]`` says which was used.
* ``"synthetic"``: always the shipped ``growjax/data/datasets/synthetic_forward.csv`` inputs (same fallback).
* a :class:`growjax.Inputs`: used as given, sampled every ``dt`` for the CSV columns.

Magnitudes: :func:`moderate_magnitude` gives, per effect, a value inside its physical range that
moves the length trace by clearly more than the 0.2 mm measurement noise within 3 s under the
published pulse (the values the effect tests use, ``tests/test_effects.py``).

Example::

    from growjax.data import synthetic
    exp = synthetic.make_experiment("active_channel_force", None, seed=1)   # moderate magnitude
    exp.write("out/acf.csv")                                                 # CSV + out/acf.json
"""

from __future__ import annotations

import collections
import dataclasses
import json
import math
from pathlib import Path
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax._hash import content_key
from growjax.data import experiment as ex
from growjax.model import effects as fx
from growjax.model.effects import Effect

# -- effects outside the catalogue (for false-claim tests) ------------------------------------------------


class OscillatingForce(Effect):
    """A zero-mean time-varying axial force on the robot, F(t) = A·sin(2π t / T) (not in the catalogue).

    Positive while it opposes growth, negative while it assists it (e.g. a periodic load from the
    tissue or a breathing patient). No catalogue effect is time-varying by itself, so a discovery
    run on data with this effect should not claim a catalogue effect with confidence.

    Attributes:
        amplitude: A, N (0 = absent).
        period: T, s.
    """

    name: ClassVar[str] = "oscillating_force"
    description: ClassVar[str] = "zero-mean sinusoidal axial force A·sin(2πt/T) on the robot (outside the catalogue)"
    units: ClassVar[dict] = {"amplitude": "N", "period": "s"}
    ranges: ClassVar[dict] = {"amplitude": (0.0, 0.2), "period": (0.1, 100.0)}
    amplitude: float = 0.0
    period: float = 2.1

    def rod_force(self, rod, state):
        return self.amplitude * jnp.sin(2.0 * jnp.pi * rod.t / self.period) + jnp.zeros_like(rod.pressure)


class HoseCompliance(Effect):
    """A hose section whose compliance grows with pressure, C(p) = k·max(p, 0) (not in the catalogue).

    It holds V(p) = k·max(p, 0)²/2 (m³) and fills through a small restriction with time constant
    τ = 5 ms: its volume ``stored_volume`` V_s follows dV_s/dt = (V(P) − V_s)/τ, and the same flow
    leaves the pressurised chamber. The catalogue's trapped air is a compliance too, but one that
    *falls* with pressure (gas); this one stiffens the other way (a bulging hose). The flow in is
    taken at the chamber pressure and the fill rate at the sensed pressure: the same pressure in the
    fast configuration, within the nozzle's drop of each other in the reference.

    Attributes:
        stiffening: k, m³/Pa² (0 = absent).
    """

    name: ClassVar[str] = "hose_compliance"
    description: ClassVar[str] = "hose compliance k·p growing with pressure (outside the catalogue)"
    units: ClassVar[dict] = {"stiffening": "m^3/Pa^2"}
    ranges: ClassVar[dict] = {"stiffening": (0.0, 1e-17)}
    state_names: ClassVar[tuple] = ("stored_volume",)
    time_constant: ClassVar[float] = 5e-3  # s: τ of the fill
    stiffening: float = 0.0

    def state_scales(self, drive):
        return (1e-8,)  # m³: ~1.5 mm of robot

    def held_volume(self, pressure):
        p = jnp.maximum(pressure, 0.0)
        return 0.5 * self.stiffening * p * p

    def chamber_outflow(self, t, pressure, state):
        return (self.held_volume(pressure) - state[0]) / self.time_constant

    def rates(self, instant, state):
        return jnp.stack([(self.held_volume(instant.pressure) - state[0]) / self.time_constant])


OUTSIDE = {cls.name: cls for cls in (OscillatingForce, HoseCompliance)}
"""Effects outside the catalogue, name → class (for tests that a discovery does not over-claim)."""

ALL_EFFECTS = {**fx.CATALOGUE, **OUTSIDE}

# Per effect: a magnitude inside its physical range that moves the length by clearly more than the
# 0.2 mm noise within 3 s (published pulse, reference parameters; see tests/test_effects.py for the
# sizes: 0.7–2.5 mm at 3 s) without driving the robot into its pressure limit.
MODERATE = {
    "active_channel_force": 0.01,  # N (2.5 mm shorter at 3 s)
    "fluid_leak": 3e-13,  # m³/(s·Pa) (0.75 mm at 3 s; 1.1 mm³/s lost at 150 kPa)
    "actuation_lag": 0.015,  # s
    "trapped_air": 0.005,  # – (α 0.005 → 0.010)
    "catheter_friction": 0.02,  # –
    "lumen_friction": 1.0,  # N/m
    "growth_rate_limit": 350.0,  # s/m
    "retraction_folding": 0.3,  # –
    "oscillating_force": 0.02,  # N
    "hose_compliance": 3e-18,  # m³/Pa² (34 mm³ held at 150 kPa)
}

SHIPPED_INPUTS = "synthetic_forward.csv"
NOISE_LENGTH_M = 2e-4
NOISE_PRESSURE_PA = 500.0


def effect_class(name: str) -> type:
    """The effect class named ``name`` (catalogue or :data:`OUTSIDE`); ValueError if unknown."""
    try:
        return ALL_EFFECTS[name]
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; known: {sorted(ALL_EFFECTS)}") from None


def magnitude_field(effect) -> str:
    """The field of an effect (name, class or instance) that :func:`make_effect`'s magnitude sets (its first)."""
    cls = effect_class(effect) if isinstance(effect, str) else (effect if isinstance(effect, type) else type(effect))
    return dataclasses.fields(cls)[0].name


def moderate_magnitude(effect: str) -> float:
    """The moderate magnitude of ``effect`` (SI, the unit of its :func:`magnitude_field`), as in the effect tests."""
    effect_class(effect)
    return MODERATE[effect]


def make_effect(effect: str, magnitude: float | None = None) -> Effect:
    """An instance of the named effect with its magnitude field set (default :func:`moderate_magnitude`).

    ValueError if the magnitude is outside the effect's physical range.
    """
    cls = effect_class(effect)
    magnitude = moderate_magnitude(effect) if magnitude is None else float(magnitude)
    field = magnitude_field(cls)
    lo, hi = cls.ranges[field]
    if not (math.isfinite(magnitude) and lo <= magnitude <= hi):
        raise ValueError(f"{effect}.{field} = {magnitude} {cls.units.get(field, '')} is outside its range [{lo}, {hi}]")
    return cls(**{field: magnitude})


def hidden_effect_parameters(effect: Effect | None = None, base=None, *, superset: bool = True, drive: str = "forward"):
    """``base`` (default :func:`growjax.reference` for ``drive``) with ``effect`` switched on.

    With ``superset`` (default) every effect of the catalogue and of :data:`OUTSIDE` is present,
    at zero (absent) except ``effect`` and any effect ``base`` already carries, in one fixed order:
    the same model, and one pytree structure for every hidden effect, so all of them share one
    compiled solver per configuration (the reference's compilation takes about a minute). The zero
    effects add states with zero rates only: the solution differs from the effect-alone model at the
    solver's tolerance.
    """
    base = gj.reference(drive) if base is None else base
    if not superset:
        return base if effect is None else gj.with_effects(base, effect)
    given = {e.name: e for e in base.effects}
    if effect is not None:
        given[effect.name] = effect
    ordered = [given.pop(name, cls()) for name, cls in ALL_EFFECTS.items()]
    return dataclasses.replace(base, effects=tuple(ordered) + tuple(given.values()))


# -- inputs --------------------------------------------------------------------------------------------------


def shipped_inputs_path() -> Path | None:
    """The shipped ``synthetic_forward.csv`` (package data ``growjax/data/datasets``)."""
    from importlib import resources

    cand = Path(str(resources.files("growjax.data") / "datasets" / SHIPPED_INPUTS))
    return cand if cand.exists() else None


def _source_experiment(kind: str, t_end: float, dt: float) -> tuple[ex.Experiment, str]:
    """(experiment whose input columns are used, description) for ``inputs="public"|"synthetic"``."""
    if kind == "public":
        folder = ex.shared_experiment_dir()
        if folder is not None:
            exp = ex.read(folder / "experiment.csv")
            return exp, (
                "public MAMMOBOT experiment (../shared/data/mammobot/experiment.csv): its catheter_length_m, "
                "published pulse 0/150 kPa (period 1.3 s, width 90 %, delay 0.26 s)"
            )
    elif kind != "synthetic":
        raise ValueError(f"inputs must be 'public', 'synthetic' or a growjax.Inputs, got {kind!r}")
    prefix = "" if kind == "synthetic" else "fallback (public experiment absent): "
    path = shipped_inputs_path()
    if path is not None:
        exp = ex.read(path)
        return exp, (
            f"{prefix}shipped {SHIPPED_INPUTS}: catheter_length_m 0.004 + 0.004 t m, published pulse "
            "0/150 kPa (period 1.3 s, width 90 %, delay 0.26 s)"
        )
    time = _grid(t_end, dt)
    return ex.Experiment(time, {"catheter_length_m": 0.004 + 0.004 * time}, "generated"), (
        f"{prefix}{SHIPPED_INPUTS} absent: catheter 0.004 + 0.004 t m, published pulse 0/150 kPa"
    )


def _grid(t_end: float, dt: float) -> np.ndarray:
    n = round(t_end / dt)
    return np.round(np.arange(1, n + 1) * dt, 10)


def _thin(time: np.ndarray, t_end: float, dt: float) -> np.ndarray:
    """Indices of the samples of ``time`` on the grid dt, 2dt, … ≤ t_end."""
    keep = time <= t_end + 1e-9
    k = np.round(time / dt)
    keep &= np.abs(time - k * dt) < 1e-6 * dt + 1e-12
    return np.flatnonzero(keep)


def _is_published(signal) -> bool:
    pub = gj.published_pulse()
    if not isinstance(signal, gj.PulseTrain):
        return False
    return all(float(getattr(signal, f)) == float(getattr(pub, f)) for f in ("amplitude", "period", "width", "delay"))


def resolve_inputs(inputs, drive: str, base, t_end: float, dt: float = 0.01):
    """(Inputs, sample times (T,), input columns {name: (T,)}, description) for ``inputs`` (see module docstring).

    The sample times are those of the source experiment on the grid ``dt`` up to ``t_end`` (s), or
    dt, 2dt, …, t_end for given Inputs. ValueError if the source ends before ``t_end``.
    """
    if isinstance(inputs, gj.Inputs):
        time = _grid(t_end, dt)
        t = jnp.asarray(time)
        cols = {"catheter_length_m": np.asarray(jax.vmap(inputs.catheter_length)(t))}
        if drive == "forward" and not _is_published(inputs.pressure_demand):
            cols["pressure_demand_Pa"] = np.asarray(jax.vmap(inputs.pressure_demand)(t))
        if drive == "inverse" and inputs.desired_length is not None:
            cols["desired_length_m"] = np.asarray(jax.vmap(inputs.desired_length)(t))
        return inputs, time, cols, "user-supplied growjax.Inputs"
    exp, description = _source_experiment(inputs, t_end, dt)
    if exp.time[-1] < t_end - 1e-9:
        raise ValueError(f"the inputs ({description}) end at {exp.time[-1]:g} s, before t_end = {t_end:g} s")
    rows = _thin(exp.time, t_end, dt)
    time = exp.time[rows]
    cols = {"catheter_length_m": np.asarray(exp["catheter_length_m"])[rows]} if "catheter_length_m" in exp else {}
    if drive == "forward":
        if "pressure_demand_Pa" in exp:
            cols["pressure_demand_Pa"] = np.asarray(exp["pressure_demand_Pa"])[rows]
        source = ex.Experiment(time, cols, exp.source)
    else:
        desired = exp["desired_length_m"] if "desired_length_m" in exp else exp["robot_length_m"]
        cols["desired_length_m"] = np.asarray(desired)[rows]
        description += "; inverse drive: its measured length as the desired length"
        source = ex.Experiment(time, cols, exp.source)
    return ex.to_inputs(source, drive, base, t1=float(time[-1])), time, cols, description


# -- the cached noise-free solve ----------------------------------------------------------------------------

_CACHE: collections.OrderedDict = collections.OrderedDict()
CACHE_SIZE = 64


def clear_cache() -> None:
    """Forget the cached noise-free reference solves."""
    _CACHE.clear()


def _effect_spec(effect, magnitude):
    """(Effect instance or None, name, magnitude or None) from the arguments of :func:`make_experiment`."""
    if effect is None:
        if magnitude not in (None, 0, 0.0):
            raise ValueError("a magnitude was given without an effect")
        return None, None, None
    if isinstance(effect, Effect):
        if magnitude is not None:
            raise ValueError("give either an Effect instance or an effect name with a magnitude, not both")
        field = magnitude_field(effect)
        return effect, effect.name, float(getattr(effect, field))
    instance = make_effect(effect, magnitude)
    return instance, effect, float(getattr(instance, magnitude_field(instance)))


def _simulate(params, model_inputs, config: gj.Config, ts) -> gj.Trajectory:
    """The one solve of the generator (``config`` is always the reference configuration)."""
    assert config.fidelity == "reference"
    return gj.simulate(params, model_inputs, config, ts=ts)


def noise_free(
    effect=None,
    magnitude: float | None = None,
    *,
    drive: str = "forward",
    inputs="public",
    t_end: float = 10.0,
    base=None,
    dt: float = 0.01,
    rtol: float = 1e-6,
    superset: bool = True,
) -> dict:
    """The noise-free reference solve behind :func:`make_experiment` (cached; same arguments).

    Returns {"time": (T,) s, "length": m, "pressure": Pa, "syringe_displacement": m, "robot_flow": m³/s,
    "columns": input columns, "inputs": description,
    "effect": Effect or None, "name", "magnitude", "status"}. Raises RuntimeError if the reference
    solver fails or the run crosses the membrane pressure limit.
    """
    instance, name, magnitude = _effect_spec(effect, magnitude)
    base_params = gj.reference(drive) if base is None else base
    inputs_key = inputs if isinstance(inputs, str) else ("inputs", content_key(inputs))
    key = (
        None if instance is None else (type(instance).__qualname__, content_key(instance)),
        drive,
        inputs_key,
        round(float(t_end), 9),
        float(dt),
        float(rtol),
        bool(superset),
        None if base is None else (content_key(base), str(jax.tree_util.tree_structure(base))),
    )
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    model_inputs, time, cols, description = resolve_inputs(inputs, drive, base_params, t_end, dt)
    params = hidden_effect_parameters(instance, base_params, superset=superset)
    config = gj.Config(fidelity="reference", drive=drive, t1=float(time[-1]), rtol=rtol, atol=rtol)
    ts = np.concatenate([[config.t0], time]) if time[0] > config.t0 else time
    traj = _simulate(params, model_inputs, config, ts)
    status = int(traj.status)
    if status != gj.OK:
        raise RuntimeError(
            f"the reference solve with {name or 'no effect'} (magnitude {magnitude}) ended with "
            f"status {gj.status_name(status)} at t = {float(traj.t_final):.3f} s"
        )
    offset = ts.size - time.size
    out = {
        "time": time,
        "length": np.asarray(traj.length)[offset:],
        "pressure": np.asarray(traj.pressure)[offset:],
        "syringe_displacement": np.asarray(traj.syringe_displacement)[offset:],
        "robot_flow": np.asarray(traj.robot_flow)[offset:],
        "columns": cols,
        "inputs": description,
        "effect": instance,
        "name": name,
        "magnitude": magnitude,
        "status": gj.status_name(status),
        "rtol": rtol,
    }
    _CACHE[key] = out
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return out


# -- the experiment ---------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class SyntheticExperiment(ex.Experiment):
    """An :class:`growjax.data.experiment.Experiment` with its truth: ``metadata`` (JSON-serialisable dict).

    ``metadata`` holds ``effect`` (name or None), ``in_catalogue``, ``parameter`` (``effect.field``),
    ``magnitude`` (SI), ``unit``, ``effect_fields`` (all fields of the hidden effect), ``noise_sd``,
    ``seed``, ``drive``, ``t_end_s``, ``inputs`` (description), ``base_parameters`` (overrides of
    :func:`growjax.reference`), ``solver`` and ``generator``.
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
    """The measured columns {column: (T,)} of a noise-free solve ``clean`` (:func:`noise_free`'s outputs), each plus
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
        effect: a name from :data:`growjax.model.effects.CATALOGUE` or :data:`OUTSIDE`, an
            :class:`growjax.Effect` instance (any fields; ``magnitude`` must then be None), or None (clean).
        magnitude: the effect's :func:`magnitude_field` (SI); None gives :func:`moderate_magnitude`.
        seed: seed of the noise (``numpy.random.default_rng``); length noise is drawn first, then pressure.
        noise_m: standard deviation of the Gaussian noise on the length, m (0.2 mm: the rig's).
        noise_pressure_Pa: standard deviation on the pressure, Pa; None leaves out the ``pressure_Pa``
            column (the public experiment has none).
        noise_syringe_m: standard deviation on the syringe displacement, m (a stepper's step count or an
            encoder: 5 µm); None (default) leaves out the ``syringe_displacement_m`` column.
        noise_flow_m3_s: standard deviation on the robot's inlet flow, m³/s; None (default) leaves out the
            ``robot_flow_m3_s`` column.
        drive: ``"forward"`` or ``"inverse"``.
        inputs: ``"public"``, ``"synthetic"`` or a :class:`growjax.Inputs` (see the module docstring,
            including the fallback when the public experiment is absent).
        t_end: end of the experiment, s (samples every ``dt`` from dt to t_end).
        base: base parameters (default :func:`growjax.reference` for the drive); effects already in
            them stay, and the hidden one is added (replacing one of the same name).
        rtol: tolerance of the reference solver (also its atol, on scaled states).
        superset: simulate in the model carrying every known effect at zero but the hidden one
            (:func:`hidden_effect_parameters`): the same model, one compiled solver for all effects.

    Returns:
        :class:`SyntheticExperiment`: columns ``robot_length_m`` (noisy), ``pressure_Pa`` (noisy, unless
        ``noise_pressure_Pa`` is None), ``syringe_displacement_m`` and ``robot_flow_m3_s`` (noisy, where their
        noise is given), the inputs ``catheter_length_m`` and, where the published pulse is
        not the demand, ``pressure_demand_Pa`` (forward) or ``desired_length_m`` (inverse), so that
        :func:`growjax.data.experiment.to_inputs` of it gives back the inputs; ``metadata`` holds the truth.
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
    return SyntheticExperiment(time, series, f"{label}, seed {seed}", meta)


def read_truth(csv_path) -> dict:
    """The metadata written beside a synthetic experiment's CSV (its ``.json``)."""
    return json.loads(Path(csv_path).with_suffix(".json").read_text())


__all__ = [
    "ALL_EFFECTS",
    "MEASURED_OUTPUTS",
    "MODERATE",
    "OUTSIDE",
    "HoseCompliance",
    "OscillatingForce",
    "SyntheticExperiment",
    "base_overrides",
    "clear_cache",
    "effect_class",
    "hidden_effect_parameters",
    "magnitude_field",
    "make_effect",
    "make_experiment",
    "moderate_magnitude",
    "noisy",
    "noise_free",
    "read_truth",
    "resolve_inputs",
]
