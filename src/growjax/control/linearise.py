"""Linear models of the plant about an operating point, from exact Jacobians of the fast configuration's field."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

import growjax as gj
from growjax.control.plant import Plant
from growjax.model.params import Parameters
from growjax.simulation import fast as fm

__all__ = ["linearize", "operating_point"]


def operating_point(
    params: Parameters,
    drive: str = "forward",
    pressure: float = 150e3,
    length: float | None = None,
    catheter: float = 0.0,
    steps: float = 0.0,
    settle: float = 1.0,
    microstep: bool = True,
) -> tuple[Plant, Float[Array, " n"], gj.Inputs]:
    """A plant at an operating point.

    Forward drive: the state after ``settle`` s at constant demand ``pressure``: growing at a steady rate above
    the yield pressure, holding below it. Inverse drive: held at step command ``steps``.

    Args:
        params: the parameters.
        drive: ``"forward"`` or ``"inverse"``.
        pressure: the constant demand, Pa.
        length: the robot length of the point, m (default: where the settling run ends).
        catheter: the catheter length in contact, m.
        steps: the step command (inverse drive).
        settle: the settling run's length, s.
        microstep: the stepper's microstepping driver (inverse drive).

    Returns:
        (the plant, its scaled state (n,), the constant inputs).
    """
    config = gj.Config(drive=drive, t1=settle)
    plant = Plant.make(params, config, microstep=microstep and drive == "inverse")
    inputs = gj.Inputs(
        catheter_length=gj.Constant(catheter), pressure_demand=gj.Constant(pressure), steps=gj.Constant(steps)
    )
    y0 = plant.initial_state()
    y, _, _ = jax.jit(lambda y: plant.advance(y, inputs, config.t0, settle, jnp.asarray([settle])))(y0)
    if length is not None:
        i = fm.layout(plant.params, drive)[0].index("robot_displacement")
        now = float(plant.outputs(settle, y, inputs)[0])
        y = y.at[i].add((length - now) / plant.scales()[i])
    return plant, y, inputs


def linearize(
    params: Parameters | None = None,
    drive: str = "forward",
    pressure: float = 150e3,
    length: float | None = None,
    catheter: float = 0.0,
    steps: float = 0.0,
    settle: float = 1.0,
) -> Any:
    """Linear model of demand → length about an operating point, as a ``control.StateSpace``.

    Forward drive: input the pressure demand (Pa), output the robot length (m); operating point after
    ``settle`` s at demand ``pressure`` (growing above the yield pressure, holding below). Inverse drive:
    input the step command (steps, continuous: a microstepping driver, `with_microstepping`),
    output the length, held at ``steps``. States are the fast configuration's scaled states.
    A, B, C from exact Jacobians (``jax.jacfwd``) of the vector field; D = 0. The operating point
    (state, rates, whether it grows) is attached as ``sys.operating_point``.
    """
    import control

    params = params if params is not None else gj.reference(drive)
    plant, y, inputs = operating_point(params, drive, pressure, length, catheter, steps, settle)
    t = jnp.asarray(settle)

    def with_u(u):
        return (
            eqx.tree_at(lambda i: i.pressure_demand, inputs, gj.Constant(u))
            if drive == "forward"
            else eqx.tree_at(lambda i: i.steps, inputs, gj.Constant(u))
        )

    u0 = jnp.asarray(pressure if drive == "forward" else steps, float)
    f = lambda y, u: plant.field(t, y, with_u(u))
    g = lambda y, u: plant.outputs(t, y, with_u(u))[0]
    a = np.asarray(jax.jacfwd(f, 0)(y, u0))
    b = np.asarray(jax.jacfwd(f, 1)(y, u0))[:, None]
    c = np.asarray(jax.jacfwd(g, 0)(y, u0))[None, :]
    d = np.asarray(jax.jacfwd(g, 1)(y, u0)).reshape(1, 1)
    names = list(fm.layout(plant.params, drive)[0])
    sys = control.ss(
        a,
        b,
        c,
        d,
        inputs=["pressure_demand" if drive == "forward" else "step_command"],
        outputs=["length"],
        states=names,
    )
    rates = np.asarray(f(y, u0))
    i = names.index("robot_displacement")
    sys.operating_point = {
        "state": np.asarray(y),
        "input": float(u0),
        "rates": rates,
        "length_m": float(g(y, u0)),
        "pressure_Pa": float(plant.outputs(t, y, with_u(u0))[1]),
        "growth_speed_m_s": float(rates[i] * plant.scales()[i]),
        "growing": bool(rates[i] * plant.scales()[i] > 1e-5),
    }
    return sys
