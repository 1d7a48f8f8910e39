"""Physical effects beyond the published model: the one extension point of both configurations.

An effect is an ``equinox.Module`` that lives in ``Parameters.effects``, so its parameters
are leaves of the parameter pytree: they can be differentiated, swept, fitted and sampled
like Y. Every effect's parameters are in SI units and zero means absent, so the extended
model reduces exactly to the base model. An effect contributes through any of five hooks,
each called by both configurations (`growjax.simulation.reference` and `growjax.simulation.fast`) from
this one definition:

* `Effect.apply`: a changed parameter (e.g. the air fraction);
* `Effect.rod_force`: a force (N) opposing growth in the rod balance of the growing element;
* `Effect.chamber_outflow`: a flow (m³/s) out of the pressurised chamber;
* `Effect.drive`: the drive force or torque actually applied, given the commanded one;
* states of its own (``state_names``), with `Effect.rates` and `Effect.length_offset`.

A rod force must not decrease with the robot velocity (friction-like); the rod balance
relies on that monotonicity to have one root. An effect whose rod force depends on the velocity
says so (``velocity_dependent``): the fast configuration then solves the rod balance by Newton
iterations instead of one fixed-point pass.

Each effect class also carries what the workflows need of it: ``moderate``, a size of its first parameter that
moves the length clearly beyond the rig's noise (synthetic data, the rival sizes of a discriminating design), and
``separated_by``, the measurement that tells it from its neighbours (the discovery's report, ``growjax effects``).

The catalogue (`CATALOGUE`, name → class): ``active_channel_force``, ``fluid_leak``,
``actuation_lag``, ``trapped_air``, ``catheter_friction``, ``lumen_friction``,
``growth_rate_limit``, ``retraction_folding``. `register` adds an effect of your own: one class is all it takes.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from growjax.model.effect_totals import (
    applied_drive,
    apply_all,
    chamber_outflow,
    initial_states,
    length_offset,
    rates,
    rod_force,
    split_states,
    state_scales,
    state_size,
)
from growjax.model.params import Parameters
from growjax.model.robot import LOCKHART_PRESSURE_SCALE, lockhart_pressure
from growjax.model.smooth import smooth_ramp

__all__ = [
    "CATALOGUE",
    "FRICTION_VELOCITY",
    "RAMP_VELOCITY",
    "BUILT_IN",
    "ActiveChannelForce",
    "ActuationLag",
    "CatheterFriction",
    "Effect",
    "FluidLeak",
    "GrowthRateLimit",
    "Instant",
    "LumenFriction",
    "RetractionFolding",
    "Rod",
    "TrappedAir",
    "applied_drive",
    "apply_all",
    "chamber_outflow",
    "friction_sign",
    "initial_states",
    "length_offset",
    "rates",
    "register",
    "rod_force",
    "split_states",
    "state_scales",
    "state_size",
    "unregister",
]

FRICTION_VELOCITY = 1e-4  # m/s: velocity over which a friction force turns from one sign to the other
RAMP_VELOCITY = 1e-6  # m/s: C¹ band of the ramps max(v, 0) of the velocity


class Rod(eqx.Module):
    """The growing element as an effect sees it in the rod balance; built by keyword only.

    Attributes:
        t: the time, s.
        pressure: sensed pressure P before the check valve, Pa.
        velocity: robot velocity (inflow / A_r), m/s.
        length: robot length, m.
        catheter_length: m.
        inner_radius: r_i of the robot, m.
        area: its annular piston area A_r = π(r_o² − r_i²), m².
    """

    _: dataclasses.KW_ONLY
    t: jax.Array
    pressure: jax.Array
    velocity: jax.Array
    length: jax.Array
    catheter_length: jax.Array
    inner_radius: jax.Array
    area: jax.Array


class Instant(eqx.Module):
    """The solved model at one instant, for the rates of effect states; built by keyword only.

    Attributes:
        t: the time, s.
        pressure: sensed pressure, Pa.
        robot_pressure: Pa.
        robot_flow: m³/s.
        velocity: robot velocity, m/s.
        length: robot length, m.
        drive: the commanded drive (forward: force on the platform, N; inverse: motor torque, N·m).
    """

    _: dataclasses.KW_ONLY
    t: jax.Array
    pressure: jax.Array
    robot_pressure: jax.Array
    robot_flow: jax.Array
    velocity: jax.Array
    length: jax.Array
    drive: jax.Array


class Effect(eqx.Module):
    """Base class of a physical effect; override only the hooks the effect uses.

    Attributes:
        name: the catalogue name, used in parameter names ``name.field`` (a class attribute).
        description: one line (a class attribute).
        units: {field: unit} of the parameter fields (a class attribute).
        ranges: {field: (low, high)} physical range of each parameter field, SI (a class attribute).
        moderate: a size of the first field, SI, inside its range, that moves the length clearly beyond the
            rig's 0.2 mm noise within 3 s of the published pulse (a class attribute).
        separated_by: the measurement that tells the effect from its neighbours (a class attribute).
        state_names: the effect's own states (a class attribute); their typical magnitudes from `state_scales`.
        velocity_dependent: whether `rod_force` depends on the robot velocity (a class attribute).
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    units: ClassVar[dict] = {}
    ranges: ClassVar[dict] = {}
    moderate: ClassVar[float] = 0.0
    separated_by: ClassVar[str] = ""
    state_names: ClassVar[tuple] = ()
    velocity_dependent: ClassVar[bool] = False  # does rod_force depend on the robot velocity?

    @classmethod
    def magnitude_field(cls) -> str:
        """The field a single size sets (the first): what `at` and ``moderate`` refer to."""
        return dataclasses.fields(cls)[0].name

    @classmethod
    def at(cls, magnitude: float | None = None) -> Effect:
        """The effect with its `magnitude_field` at ``magnitude`` (SI; None: ``moderate``), the others at default.

        Raises:
            ValueError: the magnitude is outside the field's physical range.
        """
        field = cls.magnitude_field()
        value = float(cls.moderate if magnitude is None else magnitude)
        lo, hi = cls.ranges[field]
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ValueError(
                f"{cls.name}.{field} = {value} {cls.units.get(field, '')} is outside its range [{lo}, {hi}]"
            )
        return cls(**{field: value})

    def state_scales(self, drive: str) -> tuple:
        """Typical magnitude of each state (for error control), in its SI unit."""
        return ()

    def present(self) -> jax.Array:
        """Whether any parameter of the effect is nonzero (bool array; every parameter at 0 means absent)."""
        leaves = [jnp.any(jnp.asarray(x) != 0) for x in jax.tree_util.tree_leaves(self)]
        return jnp.any(jnp.stack(leaves)) if leaves else jnp.asarray(False)

    def apply(self, params: Parameters) -> Parameters:
        """The parameters as changed by this effect (default: unchanged)."""
        return params

    def rod_force(self, rod: Rod, state: Float[Array, " m"]) -> Float[Array, "*b"]:
        """Force opposing growth on the ``rod``, N, of the shape of ``rod.pressure`` (default 0); non-decreasing in
        ``rod.velocity``. ``state``: (m,) the effect's states."""
        return jnp.zeros_like(rod.pressure)

    def chamber_outflow(
        self, t: Float[ArrayLike, ""], pressure: Float[Array, "*b"], state: Float[Array, " m"]
    ) -> Float[Array, "*b"]:
        """Flow out of the pressurised chamber at time ``t`` (s) and gauge ``pressure`` (Pa), m³/s (default 0).
        ``state``: (m,) the effect's states."""
        return jnp.zeros_like(pressure)

    def drive(self, commanded: Float[Array, "*b"], state: Float[Array, " m"]) -> Float[Array, "*b"]:
        """Drive force (N) or torque (N·m) applied, given the ``commanded`` one (default: as commanded)."""
        return commanded

    def initial_state(self, params: Parameters, drive: str) -> Float[Array, " m"]:
        """States at t0, shape (len(state_names),)."""
        return jnp.zeros(len(self.state_names))

    def rates(self, instant: Instant, state: Float[Array, " m"]) -> Float[Array, " m"]:
        """Time derivatives of the states, shape (len(state_names),)."""
        return jnp.zeros(len(self.state_names))

    def length_offset(self, state: Float[Array, " m"]) -> Float[Array, ""]:
        """Everted length (m) not produced by the volume in the robot (default 0)."""
        return jnp.asarray(0.0)


class ActiveChannelForce(Effect):
    """Constant axial pull of the active channel on the robot, opposing growth.

    Attributes:
        force: F_ac, N (0 = absent).
    """

    name: ClassVar[str] = "active_channel_force"
    description: ClassVar[str] = "constant axial force of the active channel pulling the robot back"
    units: ClassVar[dict] = {"force": "N"}
    ranges: ClassVar[dict] = {"force": (0.0, 0.5)}
    moderate: ClassVar[float] = 0.01  # N: 2.5 mm shorter at 3 s
    separated_by: ClassVar[str] = "the robot pressure during retraction, or a load cell on the active channel"
    force: float = 0.0

    def rod_force(self, rod: Rod, state: Float[Array, " m"]) -> Float[Array, "*b"]:
        """F_ac, N."""
        return self.force + jnp.zeros_like(rod.pressure)


class FluidLeak(Effect):
    """Laminar leak from the pressurised chamber to ambient, q = G·p.

    Attributes:
        conductance: G, m³/(s·Pa) (0 = absent).
    """

    name: ClassVar[str] = "fluid_leak"
    description: ClassVar[str] = "leak q = G·p from the pressurised chamber to ambient"
    units: ClassVar[dict] = {"conductance": "m^3/(s*Pa)"}
    ranges: ClassVar[dict] = {"conductance": (0.0, 1e-12)}
    moderate: ClassVar[float] = 3e-13  # m³/(s·Pa): 0.75 mm at 3 s, 1.1 mm³/s lost at 150 kPa
    separated_by: ClassVar[str] = "the pressure decay with the robot held at a fixed length"
    conductance: float = 0.0

    def chamber_outflow(
        self, t: Float[ArrayLike, ""], pressure: Float[Array, "*b"], state: Float[Array, " m"]
    ) -> Float[Array, "*b"]:
        """G·p, m³/s."""
        return self.conductance * pressure


class ActuationLag(Effect):
    """First-order lag τ between the commanded and the applied screw drive (force or torque).

    Attributes:
        time_constant: τ, s (0 = absent: the drive is applied as commanded).
    """

    name: ClassVar[str] = "actuation_lag"
    description: ClassVar[str] = "first-order lag between the commanded and the applied screw torque"
    units: ClassVar[dict] = {"time_constant": "s"}
    ranges: ClassVar[dict] = {"time_constant": (0.0, 0.5)}
    moderate: ClassVar[float] = 0.015  # s
    separated_by: ClassVar[str] = "the syringe displacement or the line pressure at a step of the demand"
    state_names: ClassVar[tuple] = ("applied_drive",)
    time_constant: float = 0.0

    def state_scales(self, drive: str) -> tuple[float, ...]:
        """The applied drive's scale: 10 N (forward) or 0.01 N·m (inverse)."""
        return (10.0,) if drive == "forward" else (1e-2,)

    def drive(self, commanded: Float[Array, "*b"], state: Float[Array, " m"]) -> Float[Array, "*b"]:
        """The lagged drive (its state), or the commanded one where τ = 0."""
        return jnp.where(self.time_constant > 0.0, state[0], commanded)

    def rates(self, instant: Instant, state: Float[Array, " m"]) -> Float[Array, " m"]:
        """(commanded − applied)/τ."""
        tau = jnp.where(self.time_constant > 0.0, self.time_constant, 1.0)
        rate = jnp.where(self.time_constant > 0.0, (instant.drive - state[0]) / tau, 0.0)
        return jnp.stack([rate])


class TrappedAir(Effect):
    """Entrained air beyond the base model's: α = α_base + Δα.

    Attributes:
        extra_fraction: Δα, relative air volume at atmospheric pressure (–) (0 = absent).
    """

    name: ClassVar[str] = "trapped_air"
    description: ClassVar[str] = "an entrained-air fraction different from the base model's"
    units: ClassVar[dict] = {"extra_fraction": "-"}
    ranges: ClassVar[dict] = {"extra_fraction": (-0.005, 0.05)}
    moderate: ClassVar[float] = 0.005  # –: α 0.005 → 0.010
    separated_by: ClassVar[str] = "the line pressure at a step of the demand (its rise time scales with the compliance)"
    extra_fraction: float = 0.0

    def apply(self, params: Parameters) -> Parameters:
        """The fluid's air fraction raised by Δα."""
        fluid = dataclasses.replace(params.fluid, air_fraction=params.fluid.air_fraction + self.extra_fraction)
        return dataclasses.replace(params, fluid=fluid)


def friction_sign(velocity: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Smooth sign tanh(v / 1e-4 m/s) of the robot velocity v (m/s): increasing, odd, ±1 beyond ~0.3 mm/s."""
    return jnp.tanh(velocity / FRICTION_VELOCITY)


class CatheterFriction(Effect):
    """Friction between catheter and membrane that resists the motion, of the paper's eq. 4 form.

    F = μ·P·2π r_i·L_c·s(v), with P the sensed pressure (taken ≥ 0: the contact cannot pull),
    r_i the robot's inner radius, L_c the catheter length in contact and s the smooth sign of the
    robot velocity (`friction_sign`). The shipped model's own catheter term (μ_c = 0.01)
    *assists* growth; this one opposes growth and retraction alike.

    Attributes:
        coefficient: μ (–) (0 = absent).
    """

    name: ClassVar[str] = "catheter_friction"
    description: ClassVar[str] = "catheter-membrane friction μ·P·2π r_i·L_c resisting the motion (paper eq. 4)"
    units: ClassVar[dict] = {"coefficient": "-"}
    ranges: ClassVar[dict] = {"coefficient": (0.0, 0.1)}
    moderate: ClassVar[float] = 0.02  # –
    separated_by: ClassVar[str] = "runs at two catheter insertion depths (the friction scales with the catheter length)"
    velocity_dependent: ClassVar[bool] = True
    coefficient: float = 0.0

    def rod_force(self, rod: Rod, state: Float[Array, " m"]) -> Float[Array, "*b"]:
        """μ·P·2π r_i·L_c·s(v), N."""
        normal = jnp.maximum(rod.pressure, 0.0) * 2.0 * jnp.pi * rod.inner_radius * rod.catheter_length  # N
        return self.coefficient * normal * friction_sign(rod.velocity)


class LumenFriction(Effect):
    """Friction of the duct wall on the everted robot, opposing the tip's motion: F = c·L·s(v).

    c = μ_s·w is the friction force per unit everted length (μ_s the wall friction coefficient,
    w the wall's normal load per unit length), L the robot length, s the smooth sign of the
    robot velocity (`friction_sign`).

    Attributes:
        force_per_length: c, N/m (0 = absent).
    """

    name: ClassVar[str] = "lumen_friction"
    description: ClassVar[str] = "duct-wall friction c·L on the everted length, opposing the tip's motion"
    units: ClassVar[dict] = {"force_per_length": "N/m"}
    ranges: ClassVar[dict] = {"force_per_length": (0.0, 10.0)}
    moderate: ClassVar[float] = 1.0  # N/m
    separated_by: ClassVar[str] = (
        "growth in free air against growth in a duct phantom (the friction scales with the length)"
    )
    velocity_dependent: ClassVar[bool] = True
    force_per_length: float = 0.0

    def rod_force(self, rod: Rod, state: Float[Array, " m"]) -> Float[Array, "*b"]:
        """c·L·s(v), N."""
        return self.force_per_length * rod.length * friction_sign(rod.velocity)


class GrowthRateLimit(Effect):
    """Membrane-limited growth speed: growing at v > 0 needs Δp = p_ref·(κ·v)^m more rod pressure.

    The inverse of a Lockhart-type law v = (Δp/p_ref)^(1/m)/κ (`growjax.model.robot.lockhart_pressure`), with
    p_ref = 1 kPa and m = 4 fixed (the calibration found Lockhart's exponent n_L ≈ 0.25, m = 1/n_L). Zero while
    the robot holds or retracts (a C¹ ramp of v). Rod force A_r·Δp.

    Attributes:
        inverse_speed: κ, s/m: the inverse of the growth speed at 1 kPa of excess pressure (0 = absent).
    """

    name: ClassVar[str] = "growth_rate_limit"
    description: ClassVar[str] = "membrane-limited growth: extra pressure p_ref·(κ·v)^4 to grow at speed v"
    units: ClassVar[dict] = {"inverse_speed": "s/m"}
    ranges: ClassVar[dict] = {"inverse_speed": (0.0, 2000.0)}
    moderate: ClassVar[float] = 350.0  # s/m
    separated_by: ClassVar[str] = "growth at two pressure amplitudes (the cap shows as a speed that no longer rises)"
    velocity_dependent: ClassVar[bool] = True
    reference_pressure: ClassVar[float] = LOCKHART_PRESSURE_SCALE  # Pa: p_ref
    exponent: ClassVar[float] = 4.0  # m = 1/n_L
    inverse_speed: float = 0.0

    def rod_force(self, rod: Rod, state: Float[Array, " m"]) -> Float[Array, "*b"]:
        """A_r·p_ref·(κ·v)^m for v > 0, N."""
        return rod.area * lockhart_pressure(rod.velocity, self.inverse_speed, self.exponent, RAMP_VELOCITY)


class RetractionFolding(Effect):
    """Folding on retraction: only k = 1 − f of the volume returned while retracting shortens the robot.

    The rest folds inside the robot (``folded_length``, F) and is not recovered when it grows
    again: dF/dt = f·max(−v, 0) (a C¹ ramp) and the length is L0 + ξ + F, with ξ the robot
    displacement the volume makes.

    Attributes:
        folding_fraction: f = 1 − k (–), in [0, 1] (0 = absent).
    """

    name: ClassVar[str] = "retraction_folding"
    description: ClassVar[str] = "a fraction f of the retracting robot folds inside instead of shortening it"
    units: ClassVar[dict] = {"folding_fraction": "-"}
    ranges: ClassVar[dict] = {"folding_fraction": (0.0, 1.0)}
    moderate: ClassVar[float] = 0.3  # –
    separated_by: ClassVar[str] = (
        "the length after a full retraction cycle, or the volume returned against the length lost"
    )
    state_names: ClassVar[tuple] = ("folded_length",)
    folding_fraction: float = 0.0

    def state_scales(self, drive: str) -> tuple[float, ...]:
        """The folded length's scale, m, as the robot displacement's."""
        return (1e-4,) if drive == "forward" else (1e-3,)  # m, as the robot displacement

    def rates(self, instant: Instant, state: Float[Array, " m"]) -> Float[Array, " m"]:
        """dF/dt = f·max(−v, 0), m/s."""
        return jnp.stack([self.folding_fraction * smooth_ramp(-instant.velocity, RAMP_VELOCITY)])

    def length_offset(self, state: Float[Array, " m"]) -> Float[Array, ""]:
        """−F, m."""
        return -state[0]  # length = L0 + ξ − offset = L0 + ξ + F


BUILT_IN = (
    ActiveChannelForce,
    FluidLeak,
    ActuationLag,
    TrappedAir,
    CatheterFriction,
    LumenFriction,
    GrowthRateLimit,
    RetractionFolding,
)
"""The package's own effects, in the catalogue's order."""

CATALOGUE = {cls.name: cls for cls in BUILT_IN}
"""Name → class of every effect discovery tests: `BUILT_IN` and those added by `register`."""


def register(cls: type[Effect]) -> type[Effect]:
    """Add an `Effect` subclass to `CATALOGUE`: discovery tests it, synthetic data and discriminating designs take it.

    The class needs a ``name`` not already in the catalogue, a one-line ``description``, exactly one parameter
    field with its unit (``units``) and physical range (``ranges``, including 0: absent), a nonzero ``moderate``
    size inside that range and a ``separated_by`` text. Usable as a class decorator.

    Returns:
        The class.

    Raises:
        TypeError: not an `Effect` subclass.
        ValueError: a declaration missing or out of range, naming it.
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        raise TypeError(f"register expects an Effect subclass, got {cls!r}")
    if not cls.name or cls.name in CATALOGUE:
        raise ValueError(f"an effect needs a name not in the catalogue ({sorted(CATALOGUE)}), got {cls.name!r}")
    if len(cls.ranges) != 1:
        raise ValueError(f"{cls.name}: discover fits one parameter per effect; ranges has {len(cls.ranges)}")
    ((field, (low, high)),) = cls.ranges.items()
    if field != cls.magnitude_field() or field not in cls.units or not low <= 0.0 <= high:
        raise ValueError(
            f"{cls.name}.{field}: needs to be its first field, a unit in `units` and a range that includes 0"
        )
    if not (cls.moderate != 0.0 and low <= cls.moderate <= high):
        raise ValueError(f"{cls.name}: needs a nonzero `moderate` size inside [{low}, {high}], got {cls.moderate}")
    if not cls.separated_by:
        raise ValueError(f"{cls.name}: needs `separated_by`, the measurement that tells it from its neighbours")
    CATALOGUE[cls.name] = cls
    return cls


def unregister(name: str) -> type[Effect]:
    """Take the effect ``name`` added by `register` out of `CATALOGUE`; returns its class.

    Raises:
        ValueError: ``name`` is not in the catalogue, or is one of the package's own effects.
    """
    own = {cls.name for cls in BUILT_IN}
    if name not in CATALOGUE or name in own:
        raise ValueError(f"{name!r} is not a registered effect; registered: {sorted(set(CATALOGUE) - own)}")
    return CATALOGUE.pop(name)
