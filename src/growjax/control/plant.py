"""A configuration of the model as a plant: stepped from its state tick by tick through
`growjax.simulation.simulate.simulate_from` (the configuration's own solver and settings), with the vector field and
outputs of a state for linear models and state estimates. SI units."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

import growjax as gj
from growjax.model import effects as fx
from growjax.simulation import fast as fm
from growjax.simulation import reference as rm
from growjax.simulation.simulate import simulate_from

if TYPE_CHECKING:
    from growjax.control.targets import Target

__all__ = ["TICK_STEPS", "Plant", "catheter_signal", "segment_inputs", "with_microstepping"]

# Step budget of one tick, per fidelity (a tick spans at most a few hundred steps).
TICK_STEPS = {"fast": 400, "reference": 20_000}


def with_microstepping(params: gj.Parameters, on: bool = True) -> gj.Parameters:
    """``params`` with the stepper's driver swapped for the sine–cosine microstepping one (both configurations;
    `growjax.model.motor.winding_voltages`), or back to full steps where not ``on``: with it the step command may
    be any real number."""
    return eqx.tree_at(lambda p: p.motor, params, dataclasses.replace(params.motor, microstepping=on))


class Plant(eqx.Module):
    """A configuration of the model as a plant: (params, config, the assembly's prepared constants).

    ``config`` is the simulation's, made explicit (`growjax.Config.resolved`), with the pressure limit
    flagged rather than stopping a tick and a tick's step budget (`TICK_STEPS`) unless it sets one.
    ``microstep`` swaps the stepper's full-step driver for the microstepping one (`with_microstepping`).

    Attributes:
        params: the parameters.
        config: the configuration, resolved.
        prep: the configuration's prepared constants (``growjax.simulation.fast.prepare`` or the reference's).
    """

    params: object
    config: gj.Config = eqx.field(static=True)
    prep: object

    @classmethod
    def make(cls, params: gj.Parameters, config: gj.Config, microstep: bool = False) -> Plant:
        """The plant of ``params`` under ``config``.

        Args:
            params: the parameters.
            config: the simulation's configuration.
            microstep: the stepper's microstepping driver in place of its full-step one.

        Returns:
            The plant.

        Raises:
            ValueError: for microstepping with the forward drive.
        """
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

    def applied(self) -> gj.Parameters:
        """The parameters with every effect's parameter change applied (what the field sees)."""
        return fx.apply_all(self.params)

    def initial_state(self) -> Float[Array, " n"]:
        """The scaled state at rest."""
        return self._module(self.config).initial_state(self.applied(), self.config)

    def scales(self) -> Float[Array, " n"]:
        """The state's scales, SI per unit of the scaled state."""
        return jnp.asarray(self._module(self.config).layout(self.params, self.config.drive)[1])

    def field(self, t: Float[ArrayLike, ""], y: Float[Array, " n"], inputs: gj.Inputs) -> Float[Array, " n"]:
        """Scaled state rates (the solver's field) at time ``t`` (s) and scaled state ``y``."""
        return self._module(self.config).vector_field(t, y, (self.applied(), inputs, self.config, self.prep))

    def outputs(
        self, t: Float[ArrayLike, ""], y: Float[Array, " n"], inputs: gj.Inputs
    ) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
        """(length m, sensed pressure Pa, syringe displacement m) of a scaled state ``y`` at time ``t`` (s)."""
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
        ta: Float[ArrayLike, ""],
        tb: Float[ArrayLike, ""],
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


def segment_inputs(
    catheter: gj.Sampled,
    ta: Float[ArrayLike, ""],
    tb: Float[ArrayLike, ""],
    ua: Float[ArrayLike, ""],
    ub: Float[ArrayLike, ""],
    steps: Float[ArrayLike, ""],
) -> gj.Inputs:
    """Inputs of one tick: the demand ramps from ``ua`` at ``ta`` to ``ub`` at ``tb`` (Pa, s; first-order hold),
    the step command held at ``steps``, the catheter length ``catheter`` (m)."""
    return gj.Inputs(
        catheter_length=catheter,
        pressure_demand=gj.Sampled(jnp.stack([ta, tb]), jnp.stack([ua, ub])),
        steps=gj.Constant(steps),
    )


def catheter_signal(target: Target) -> gj.Sampled:
    """The catheter length of a `growjax.control.targets.Target` as an input signal (m)."""
    return gj.Sampled(np.asarray(target.time, float), np.asarray(target.catheter, float))
