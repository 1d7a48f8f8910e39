"""Effects outside the catalogue, for tests that a discovery does not claim a catalogue effect it cannot have seen."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from growjax.model.effects import Effect

__all__ = ["OUTSIDE", "HoseCompliance", "OscillatingForce"]


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
    moderate: ClassVar[float] = 0.02  # N
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
    moderate: ClassVar[float] = 3e-18  # m³/Pa²: 34 mm³ held at 150 kPa
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
