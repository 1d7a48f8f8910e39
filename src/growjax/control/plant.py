"""A configuration of the model as a plant: stepped from its state tick by tick through
`growjax.simulation.simulate.simulate_from` (the configuration's own solver and settings), with the vector field and
outputs of a state for linear models and state estimates. SI units."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

import growjax as gj
from growjax.model import effects as fx
from growjax.simulation import fast as fm
from growjax.simulation import reference as rm
from growjax.simulation.simulate import simulate_from

__all__ = ["TICK_STEPS", "Plant", "catheter_signal", "segment_inputs", "with_microstepping"]

# Step budget of one tick, per fidelity (a tick spans at most a few hundred steps).
TICK_STEPS = {"fast": 400, "reference": 20_000}


def with_microstepping(params, on: bool = True):
    """``params`` with the stepper's driver swapped for the sine–cosine microstepping one (both configurations;
    `growjax.model.motor.winding_voltages`): the step command may then be any real number."""
    return eqx.tree_at(lambda p: p.motor, params, dataclasses.replace(params.motor, microstepping=on))


class Plant(eqx.Module):
    """A configuration of the model as a plant: (params, config, the assembly's prepared constants).

    ``config`` is the simulation's, made explicit (`growjax.Config.resolved`), with the pressure limit
    flagged rather than stopping a tick and a tick's step budget (`TICK_STEPS`) unless it sets one.
    ``microstep`` swaps the stepper's full-step driver for the microstepping one (`with_microstepping`).
    """

    params: object
    config: gj.Config = eqx.field(static=True)
    prep: object

    @classmethod
    def make(cls, params, config: gj.Config, microstep: bool = False) -> Plant:
        if microstep and config.drive != "inverse":
            raise ValueError("microstepping is a driver of the stepper (inverse) drive")
        params = with_microstepping(params) if microstep else params
        config = config.replace(
            stop_at_pressure_limit=False, max_steps=config.max_steps or TICK_STEPS[config.fidelity]
        ).resolved()
        return cls(params, config, cls._module(config).prepare(fx.apply_all(params), config))

    @staticmethod
    def _module(config: gj.Config):
        return fm if config.fidelity == "fast" else rm

    @property
    def microstep(self) -> bool:
        """Does the stepper's driver microstep?"""
        return bool(self.params.motor.microstepping)

    def applied(self):
        """The parameters with every effect's parameter change applied (what the field sees)."""
        return fx.apply_all(self.params)

    def initial_state(self) -> Float[Array, " n"]:
        """The scaled state at rest."""
        return self._module(self.config).initial_state(self.applied(), self.config)

    def scales(self) -> Float[Array, " n"]:
        return jnp.asarray(self._module(self.config).layout(self.params, self.config.drive)[1])

    def field(self, t, y, inputs) -> Float[Array, " n"]:
        """Scaled state rates (the solver's field)."""
        return self._module(self.config).vector_field(t, y, (self.applied(), inputs, self.config, self.prep))

    def outputs(self, t, y, inputs):
        """(length m, sensed pressure Pa, syringe displacement m) of a scaled state."""
        applied = self.applied()
        if self.config.fidelity == "fast":
            length, pressure, _, x_p, _ = fm.rates(t, y * self.scales(), applied, inputs, self.config, self.prep)[1]
            return length, pressure, x_p
        out = rm.outputs(t, y, applied, inputs, self.config, self.prep)
        return out["length"], out["pressure"], out["syringe_displacement"]

    def advance(
        self,
        y: Float[Array, " n"],
        inputs: gj.Inputs,
        ta,
        tb,
        ts: Float[Array, " S"],
        knots: Float[Array, " K"] | None = None,
    ) -> tuple[Float[Array, " n"], tuple, Int[Array, ""]]:
        """Integrate from state ``y`` at ``ta`` to ``tb`` (s) → (state at tb, outputs at ``ts`` (S,) each, status:
        0 reached tb, 2 failed).

        ``knots``: times (s) inside the interval where the inputs' slope breaks (stepped onto).
        """
        ts = jnp.clip(ts, ta, tb)  # rounding of ta + k·dt must not leave the interval
        beyond = jnp.full((1,), tb + 1.0)
        kinks = beyond if knots is None else jnp.concatenate([knots, beyond])
        traj = simulate_from(self.params, inputs, self.config, y, (ta, tb), ts, (beyond, kinks))
        status = jnp.where(traj.status == gj.SOLVER_FAILED, 2, 0)
        return traj.final_state, (traj.length, traj.pressure, traj.syringe_displacement), status


def segment_inputs(catheter, ta, tb, ua, ub, steps):
    """Inputs of one tick: the demand ramps from ``ua`` at ``ta`` to ``ub`` at ``tb`` (first-order hold)."""
    return gj.Inputs(
        catheter_length=catheter,
        pressure_demand=gj.Sampled(jnp.stack([ta, tb]), jnp.stack([ua, ub])),
        steps=gj.Constant(steps),
    )


def catheter_signal(target):
    """The catheter length of a `growjax.control.targets.Target` as an input signal (m)."""
    return gj.Sampled(np.asarray(target.time, float), np.asarray(target.catheter, float))
