"""All model parameters as one typed pytree, with override by name and validation.

Values are the shipped model's, SI units throughout. A parameter
is addressed as ``block.field`` (``robot.yield_pressure``), by its bare field name
when that is unique, or by the published symbol (``Y``, ``ext``, ``n``, ``As`` …).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import numpy as np
from jaxtyping import ArrayLike, Bool, Float

from growjax.model.fluid import Fluid
from growjax.model.hydraulics import (
    CheckValve,
    DirectionalValve,
    Nozzle,
    Orifice,
    Pipeline,
    circular_pipeline,
)
from growjax.model.motor import PID, StepperMotor
from growjax.model.pump import SyringePump
from growjax.model.robot import GrowingRobot

__all__ = [
    "ALIASES",
    "DRIVES",
    "Parameters",
    "admissible_rows",
    "as_dict",
    "get",
    "parameter_names",
    "physical_ranges",
    "reference",
    "replace",
    "resolve_name",
    "validate",
    "with_effects",
]

DRIVES = ("forward", "inverse")  # pressure demand with an ideal torque source; desired length with the stepper


class Parameters(eqx.Module):
    """Every physical parameter of the MAMMOBOT drive chain, grouped by subsystem (see each block's docstring).

    Attributes:
        fluid: the working fluid.
        pump: the syringe pump.
        tube: each syringe's hose.
        orifice: the orifice between the hoses and the tank.
        tank: the tank.
        nozzle: the nozzle into the robot.
        check_valve: the check valve.
        valve: the 3-way directional valve.
        robot: the growing robot.
        pid: the forward drive's pressure PID.
        motor: the inverse drive's stepper.
        effects: the physical effects added to the published model (`growjax.model.effects`); their parameters
            are addressed as ``effect_name.field``.
    """

    fluid: Fluid
    pump: SyringePump
    tube: Pipeline
    orifice: Orifice
    tank: Pipeline
    nozzle: Nozzle
    check_valve: CheckValve
    valve: DirectionalValve
    robot: GrowingRobot
    pid: PID
    motor: StepperMotor
    effects: tuple = ()


ALIASES = {
    "Y": "robot.yield_pressure",
    "ext": "robot.extensibility",
    "phi": "robot.extensibility",
    "n": "robot.growth_exponent",
    "phi_L": "robot.lockhart_rate",
    "n_L": "robot.lockhart_exponent",
    "ri": "robot.inner_radius",
    "ro": "robot.outer_radius",
    "t": "robot.membrane_thickness",
    "yieldstress": "robot.membrane_yield_stress",
    "mu_c": "robot.catheter_friction",
    "F_AC": "robot.active_channel_force",
    "As": "pump.syringe_area",
    "Kp": "pid.proportional",
    "Ki": "pid.integral",
    "Kd": "pid.derivative",
    "f": "motor.controller_rate",
}


def reference(drive: str = "forward", growth_law: str = "reference") -> Parameters:
    """The shipped Simscape model's parameters.

    Args:
        drive: ``"forward"`` (ideal torque) or ``"inverse"`` (stepper).
        growth_law: ``"reference"``, or ``"lockhart"``: Lockhart's law in place of the published velocity term
            (see `growjax.model.robot`).

    Returns:
        The parameters.

    Raises:
        ValueError: for an unknown drive or growth law.
    """
    if drive not in DRIVES:
        raise ValueError(f"drive must be one of {DRIVES}, got {drive!r}")
    tube_length = 0.3 if drive == "forward" else 0.1
    stroke = 0.08 if drive == "forward" else 0.1
    tube = circular_pipeline(
        4e-3, tube_length, diameter_compliance=2e-12, wall_time_constant=0.01, initial_pressure=200.0
    )
    tank = Pipeline(area=1.695e-4, hydraulic_diameter=0.015, length=0.122, initial_pressure=1.0)
    return Parameters(
        fluid=Fluid(),
        pump=SyringePump(),
        tube=tube,
        orifice=Orifice(),
        tank=tank,
        nozzle=Nozzle(),
        check_valve=CheckValve(),
        valve=DirectionalValve(),
        robot=GrowingRobot(stroke=stroke, hard_stop_bound=stroke, growth_law=growth_law),
        pid=PID(),
        motor=StepperMotor(),
    )


def _blocks(params: Parameters):
    """{name: module} of every parameter block, effects included (by their catalogue name)."""
    blocks = {f.name: getattr(params, f.name) for f in dataclasses.fields(params) if f.name != "effects"}
    for effect in params.effects:
        if effect.name in blocks:
            raise ValueError(f"effect {effect.name!r} appears twice or clashes with a parameter block")
        blocks[effect.name] = effect
    return blocks


def parameter_names(params: Parameters) -> list[str]:
    """Qualified names ``block.field`` of every numeric parameter of ``params`` (effects as ``effect_name.field``)."""
    names = []
    for block_name, block in _blocks(params).items():
        for f in dataclasses.fields(block):
            if not f.metadata.get("static", False):
                names.append(f"{block_name}.{f.name}")
    return names


def resolve_name(params: Parameters, name: str) -> str:
    """The qualified name of a parameter.

    Args:
        params: the parameters (their effects add names).
        name: an alias (`ALIASES`), a bare field name or ``block.field``.

    Returns:
        ``block.field``.

    Raises:
        ValueError: for an unknown or ambiguous name.
    """
    name = ALIASES.get(name, name)
    names = parameter_names(params)
    if name in names:
        return name
    matches = [q for q in names if q.split(".", 1)[1] == name]
    if len(matches) == 1:
        return matches[0]
    if len(matches) > 1:
        raise ValueError(f"parameter name {name!r} is ambiguous: use one of {matches}")
    raise ValueError(f"unknown parameter {name!r}; known: {sorted(ALIASES)} or block.field from {names}")


def get(params: Parameters, name: str) -> Any:
    """The value of a parameter (``name`` as `resolve_name` takes it); ValueError for an unknown name."""
    block, field = resolve_name(params, name).split(".")
    return getattr(_blocks(params)[block], field)


def replace(params: Parameters, **values: Any) -> Parameters:
    """A copy of ``params`` with the named parameters replaced.

    Args:
        params: the parameters.
        **values: {name: value}, names as `resolve_name` takes them, values SI (numbers or arrays).

    Returns:
        The copy.

    Raises:
        ValueError: for an unknown or ambiguous name.
    """
    by_block: dict[str, dict] = {}
    for name, value in values.items():
        block, field = resolve_name(params, name).split(".")
        by_block.setdefault(block, {})[field] = value
    effects = tuple(dataclasses.replace(e, **by_block.pop(e.name)) if e.name in by_block else e for e in params.effects)
    updates = {b: dataclasses.replace(getattr(params, b), **kw) for b, kw in by_block.items()}
    return dataclasses.replace(params, effects=effects, **updates)


def with_effects(params: Parameters, *effects: eqx.Module) -> Parameters:
    """``params`` with the given effects (`growjax.model.effects`) added, or replaced by catalogue name."""
    names = {e.name for e in effects}
    kept = tuple(e for e in params.effects if e.name not in names)
    return dataclasses.replace(params, effects=kept + tuple(effects))


def as_dict(params: Parameters) -> dict[str, float]:
    """Flat ``{block.field: value}`` of every scalar parameter (for JSON and tables)."""
    out = {}
    for q in parameter_names(params):
        v = get(params, q)
        if v is None:
            continue
        a = np.asarray(v)
        out[q] = float(a) if a.ndim == 0 else a.tolist()
    return out


# Physical admissible ranges of the parameters most often changed by hand or by a sampler.
_RANGES = {
    "robot.yield_pressure": (0.0, 1e6, "Pa"),
    "robot.extensibility": (1e-12, math.inf, "(m/s)·Pa^(-1/n)"),
    "robot.growth_exponent": (0.05, 5.0, "-"),
    "robot.lockhart_rate": (1e-12, 10.0, "m/s"),
    "robot.lockhart_exponent": (0.05, 5.0, "-"),
    "robot.inner_radius": (0.0, 0.05, "m"),
    "robot.outer_radius": (1e-5, 0.05, "m"),
    "robot.membrane_thickness": (1e-7, 1e-2, "m"),
    "robot.catheter_friction": (0.0, 10.0, "-"),
    "robot.initial_length": (0.0, 1.0, "m"),
    "robot.stroke": (1e-4, 2.0, "m"),
    "pump.syringe_area": (1e-7, 1e-1, "m^2"),
    "fluid.density": (100.0, 5000.0, "kg/m^3"),
    "fluid.air_fraction": (0.0, 0.5, "-"),
    "motor.controller_rate": (1e-3, 1e5, "Hz"),
}


def physical_ranges(params: Parameters) -> dict[str, tuple[float, float, str]]:
    """{qualified name: (low, high, unit)}: the physical range of each parameter that has one (effects included)."""
    ranges = dict(_RANGES)
    for e in params.effects:
        for field, (lo, hi) in e.ranges.items():
            ranges[f"{e.name}.{field}"] = (lo, hi, e.units.get(field, ""))
    return ranges


def admissible_rows(base: Parameters, names: Sequence[str], values: Float[ArrayLike, "n d"]) -> Bool[np.ndarray, " n"]:
    """Which rows of parameter values are finite and in their physical ranges, in one pass over the rows.

    Args:
        base: the parameters the rows replace fields of.
        names: the d parameters' names.
        values: (n, d) their values, SI.

    Returns:
        (n,) bool, the admissible rows.

    Raises:
        ValueError: naming a parameter not in ``names`` that is not admissible (checked once).
    """
    values = np.atleast_2d(np.asarray(values, float))
    names = [resolve_name(base, n) for n in names]
    ranges = physical_ranges(base)
    ok = np.all(np.isfinite(values), axis=1)
    for j, q in enumerate(names):
        if q in ranges:
            lo, hi, _ = ranges[q]
            ok &= (values[:, j] >= lo) & (values[:, j] <= hi)
    radii = {q: values[:, j] for j, q in enumerate(names) if q in ("robot.inner_radius", "robot.outer_radius")}
    if radii:
        inner = radii.get("robot.inner_radius", float(base.robot.inner_radius))
        outer = radii.get("robot.outer_radius", float(base.robot.outer_radius))
        ok &= np.asarray(inner < outer)
    if np.any(ok):
        validate(replace(base, **dict(zip(names, map(float, values[np.argmax(ok)])))))
    return ok


def validate(params: Parameters) -> None:
    """Check that every parameter is finite and inside its physical range, on concrete (possibly batched) values,
    never inside ``jit``.

    Args:
        params: the parameters.

    Raises:
        ValueError: naming the first parameter that is non-finite or outside its physical range.
    """
    ranges = physical_ranges(params)
    for q in parameter_names(params):
        v = get(params, q)
        if v is None or isinstance(v, jax.core.Tracer):
            continue
        a = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"parameter {q} is not finite: {v}")
        if q in ranges:
            lo, hi, unit = ranges[q]
            if np.any(a < lo) or np.any(a > hi):
                raise ValueError(f"parameter {q} = {v} {unit} is outside its physical range [{lo}, {hi}] {unit}")
    r = params.robot
    if np.any(np.asarray(r.inner_radius) >= np.asarray(r.outer_radius)):
        raise ValueError("parameter robot.inner_radius must be smaller than robot.outer_radius")


@dataclasses.dataclass(frozen=True)
class Dimension:
    """One parameter's box: qualified ``name`` (``block.field``), bounds in SI units, linear or log scale."""

    name: str
    low: float
    high: float
    log: bool = False

    def __post_init__(self):
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or not self.high > self.low:
            raise ValueError(f"{self.name}: need finite LOW < HIGH, got {self.low}:{self.high}")
        if self.log and self.low <= 0:
            raise ValueError(f"{self.name}: a log scale needs LOW > 0, got {self.low}")

    def from_unit(self, u):
        """Map u ∈ [0, 1] to the parameter value."""
        u = np.asarray(u, float)
        if self.log:
            return np.exp(np.log(self.low) + u * (np.log(self.high) - np.log(self.low)))
        return self.low + u * (self.high - self.low)


def paper_box() -> tuple[Dimension, ...]:
    """The published investigation: n 0.9–1.1, Y 5–15 kPa, ext 4000–10000."""
    return (
        Dimension("robot.growth_exponent", 0.9, 1.1),
        Dimension("robot.yield_pressure", 5e3, 15e3),
        Dimension("robot.extensibility", 4000.0, 10000.0),
    )


def latin_hypercube(dims, n: int, seed: int) -> np.ndarray:
    """(n, d) Latin-hypercube design in parameter units over the boxes ``dims`` (d,) of :class:`Dimension`
    (``scipy.stats.qmc.LatinHypercube``, seeded)."""
    from scipy.stats import qmc

    if n < 1:
        raise ValueError(f"a Latin hypercube needs n ≥ 1 points, got {n}")
    unit = qmc.LatinHypercube(d=len(dims), seed=np.random.default_rng(seed)).random(n)
    return np.column_stack([d.from_unit(unit[:, i]) for i, d in enumerate(dims)])
