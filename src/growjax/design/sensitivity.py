"""The model's length and pressure under an input, with their sensitivities to w = (ln θ, b): one forward
sensitivity solve of the fast configuration.

The solve is plain JAX (the Rosenbrock integrator's loop, `growjax.simulation.simulate.forward_sensitivities`), so
forward mode differentiates it again: ``jax.jvp`` of `solve` along a change of the input gives the
sensitivities' own derivatives, and with them the gradient of any criterion built on them with respect to the
design (a while loop, so forward mode only: one tangent per design variable).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from growjax.model import params as gp
from growjax.model.signals import Inputs
from growjax.simulation.config import Config
from growjax.simulation.simulate import Breaks, forward_sensitivities, simulate
from growjax.simulation.trajectory import OK

__all__ = ["Sensitivities", "moved", "remainder", "solve", "solve_along"]


class Sensitivities(NamedTuple):
    """On the sample times (n,): ``length`` m and ``pressure`` Pa; ``jac_length`` (n, m) m and ``jac_pressure``
    (n, m) Pa per unit of w = (ln θ, b); ``ok`` whether the run reached its end. Past a failure: NaN.

    Attributes:
        length: (n,) m.
        pressure: (n,) Pa.
        jac_length: (n, m) m per unit of w.
        jac_pressure: (n, m) Pa per unit of w.
        ok: bool, the run reached its end.
    """

    length: jax.Array
    pressure: jax.Array
    jac_length: jax.Array
    jac_pressure: jax.Array
    ok: jax.Array


def moved(
    base: gp.Parameters, names: tuple[str, ...], rig: tuple[str, ...], z: Float[ArrayLike, " w"]
) -> gp.Parameters:
    """``base`` at the point z (p + q,) of w = (ln θ/θ̂ for ``names``, ln ψ/ψ₀ for the ``rig``) (traceable)."""
    return gp.replace(base, **{n: gp.get(base, n) * jnp.exp(z[i]) for i, n in enumerate((*names, *rig))})


def solve(
    base: gp.Parameters,
    inputs: Inputs,
    names: tuple[str, ...],
    rig: tuple[str, ...],
    config: Config,
    ts: Float[ArrayLike, " n"],
    breaks: Breaks,
    z: Float[ArrayLike, " w"] | None = None,
) -> Sensitivities:
    """One sensitivity solve along w = (ln θ for ``names``, ln ψ/ψ₀ for the ``rig``) at the point ``z`` (p + q,) of
    w (default 0: the estimate on the nominal rig). Traceable in ``inputs``, ``base`` and ``z``; ``config``
    resolved (forward adjoint), ``breaks`` the inputs' (jump, slope-break) times, ``ts`` (n,) s."""
    p, q = len(names), len(rig)
    z = jnp.zeros(p + q) if z is None else jnp.asarray(z)
    return solve_along(lambda w: moved(base, names, rig, z + w), p + q, inputs, config, ts, breaks)


def solve_along(
    params_of: Callable[[Float[Array, " m"]], gp.Parameters],
    m: int,
    inputs: Inputs,
    config: Config,
    ts: Float[ArrayLike, " n"],
    breaks: Breaks,
) -> Sensitivities:
    """One sensitivity solve along the m coordinates w of ``params_of(w) → Parameters`` (traceable) at w = 0; the
    rest as `solve`."""
    traj, tangents = forward_sensitivities(params_of, jnp.zeros(m), inputs, config, jnp.asarray(ts), breaks)
    return Sensitivities(traj.length, traj.pressure, tangents["length"].T, tangents["pressure"].T, traj.status == OK)


def remainder(
    base: gp.Parameters,
    inputs: Inputs,
    names: tuple[str, ...],
    rig: tuple[str, ...],
    config: Config,
    ts: Float[ArrayLike, " n"],
    breaks: Breaks,
    s: Sensitivities,
    offsets: Float[ArrayLike, "D q"],
    z: Float[ArrayLike, " w"] | None = None,
) -> Float[Array, "n D"]:
    """R (n, D) m: what the rig's linearised effect misses, L(b + b_k) − L(b) − G b_k for each row b_k of
    ``offsets`` (D, q) (the rig's relative errors) about the point ``z`` (p + q,) of w (default 0); ``s`` the
    sensitivities there (G its rig columns). One plain solve per draw and one at the point (traceable)."""
    p, q = len(names), len(rig)
    z = jnp.zeros(p + q) if z is None else jnp.asarray(z)

    def run(b):
        point = z + jnp.concatenate([jnp.zeros(p), b])
        return simulate(moved(base, names, rig, point), inputs, config, ts=ts, breaks=breaks).length

    offsets = jnp.asarray(offsets)
    lengths = jax.vmap(run)(jnp.concatenate([jnp.zeros((1, q)), offsets]))  # (1 + D, n)
    return (lengths[1:] - lengths[0]).T - s.jac_length[:, p:] @ offsets.T
