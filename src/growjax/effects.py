"""Physical effects beyond the published model: the one extension point of both configurations.

An effect is an ``equinox.Module`` that lives in ``Parameters.effects``, so its parameters
are leaves of the parameter pytree: they can be differentiated, swept, fitted and sampled
like Y. Every effect's parameters are in SI units and zero means absent, so the extended
model reduces exactly to the base model. An effect contributes through any of five hooks,
each called by both configurations (:mod:`growjax.reference_model` and :mod:`growjax.fast_model`) from
this one definition:

* :meth:`Effect.apply`: a changed parameter (e.g. the air fraction);
* :meth:`Effect.rod_force`: a force (N) opposing growth in the rod balance of the growing element;
* :meth:`Effect.chamber_outflow`: a flow (m³/s) out of the pressurised chamber;
* :meth:`Effect.drive`: the drive force or torque actually applied, given the commanded one;
* states of its own (``state_names``), with :meth:`Effect.rates` and :meth:`Effect.length_offset`.

A rod force must not decrease with the robot velocity (friction-like); the rod balance
relies on that monotonicity to have one root.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp


class Rod(NamedTuple):
    """The growing element as an effect sees it in the rod balance (SI units).

    t: s.  pressure: sensed pressure P before the check valve, Pa.  velocity: robot
    velocity (inflow / A_r), m/s.  length: robot length, m.  catheter_length: m.
    """

    t: jax.Array
    pressure: jax.Array
    velocity: jax.Array
    length: jax.Array
    catheter_length: jax.Array


class Instant(NamedTuple):
    """The solved model at one instant, for the rates of effect states (SI units).

    ``drive``: the commanded drive (forward: force on the platform, N; inverse: motor torque, N·m).
    """

    t: jax.Array
    pressure: jax.Array
    robot_pressure: jax.Array
    robot_flow: jax.Array
    velocity: jax.Array
    length: jax.Array
    drive: jax.Array


class Effect(eqx.Module):
    """Base class of a physical effect; override only the hooks the effect uses.

    Class attributes: ``name`` (catalogue name, used in parameter names ``name.field``),
    ``description`` (one line), ``units`` and ``ranges`` (per parameter field),
    ``state_names`` (states of its own; their typical magnitudes from :meth:`state_scales`),
    ``velocity_dependent`` (whether :meth:`rod_force` depends on the robot velocity).
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    units: ClassVar[dict] = {}
    ranges: ClassVar[dict] = {}
    state_names: ClassVar[tuple] = ()
    velocity_dependent: ClassVar[bool] = False  # does rod_force depend on the robot velocity?

    def state_scales(self, drive: str) -> tuple:
        """Typical magnitude of each state (for error control), in its SI unit."""
        return ()

    def apply(self, params):
        """The parameters as changed by this effect (default: unchanged)."""
        return params

    def rod_force(self, rod: Rod, state) -> jax.Array:
        """Force opposing growth on the rod, N (default 0); non-decreasing in ``rod.velocity``."""
        return jnp.zeros_like(rod.pressure)

    def chamber_outflow(self, t, pressure, state) -> jax.Array:
        """Flow out of the pressurised chamber at gauge ``pressure`` (Pa), m³/s (default 0)."""
        return jnp.zeros_like(pressure)

    def drive(self, commanded, state) -> jax.Array:
        """Drive force (N) or torque (N·m) applied, given the ``commanded`` one (default: as commanded)."""
        return commanded

    def initial_state(self, params, drive: str) -> jax.Array:
        """States at t0, shape (len(state_names),)."""
        return jnp.zeros(len(self.state_names))

    def rates(self, instant: Instant, state) -> jax.Array:
        """Time derivatives of the states, shape (len(state_names),)."""
        return jnp.zeros(len(self.state_names))

    def length_offset(self, state) -> jax.Array:
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
    force: float = 0.0

    def rod_force(self, rod, state):
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
    conductance: float = 0.0

    def chamber_outflow(self, t, pressure, state):
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
    state_names: ClassVar[tuple] = ("applied_drive",)
    time_constant: float = 0.0

    def state_scales(self, drive):
        return (10.0,) if drive == "forward" else (1e-2,)

    def drive(self, commanded, state):
        return jnp.where(self.time_constant > 0.0, state[0], commanded)

    def rates(self, instant, state):
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
    extra_fraction: float = 0.0

    def apply(self, params):
        import dataclasses

        fluid = dataclasses.replace(params.fluid, air_fraction=params.fluid.air_fraction + self.extra_fraction)
        return dataclasses.replace(params, fluid=fluid)


CATALOGUE = {cls.name: cls for cls in (ActiveChannelForce, FluidLeak, ActuationLag, TrappedAir)}


# -- what the assemblies call: the sum over a tuple of effects -------------------------------------------


def split_states(effects, states):
    """The state vector of all effects (K,) → one array per effect."""
    out, k = [], 0
    for e in effects:
        m = len(e.state_names)
        out.append(states[k:k + m])
        k += m
    return out


def state_size(effects) -> int:
    return sum(len(e.state_names) for e in effects)


def state_scales(effects, drive: str) -> tuple:
    return tuple(s for e in effects for s in e.state_scales(drive))


def initial_states(effects, params, drive: str) -> jax.Array:
    parts = [jnp.asarray(e.initial_state(params, drive), float) for e in effects if e.state_names]
    return jnp.concatenate(parts) if parts else jnp.zeros(0)


def apply_all(params):
    """The parameters with every effect's parameter change applied."""
    for e in params.effects:
        params = e.apply(params)
    return params


def rod_force(effects, states, rod: Rod):
    total = jnp.zeros_like(rod.pressure)
    for e, s in zip(effects, split_states(effects, states)):
        total = total + e.rod_force(rod, s)
    return total


def chamber_outflow(effects, states, t, pressure):
    total = jnp.zeros_like(pressure)
    for e, s in zip(effects, split_states(effects, states)):
        total = total + e.chamber_outflow(t, pressure, s)
    return total


def applied_drive(effects, states, commanded):
    for e, s in zip(effects, split_states(effects, states)):
        commanded = e.drive(commanded, s)
    return commanded


def length_offset(effects, states):
    total = jnp.asarray(0.0)
    for e, s in zip(effects, split_states(effects, states)):
        total = total + e.length_offset(s)
    return total


def rates(effects, states, instant: Instant):
    parts = [jnp.asarray(e.rates(instant, s), float) for e, s in zip(effects, split_states(effects, states)) if e.state_names]
    return jnp.concatenate(parts) if parts else jnp.zeros(0)
