"""The sums over a tuple of effects that both configurations' assemblies call: each hook of
`growjax.model.effects.Effect` totalled over ``params.effects``, with their states packed in one vector."""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = [
    "applied_drive",
    "apply_all",
    "chamber_outflow",
    "initial_states",
    "length_offset",
    "rates",
    "rod_force",
    "split_states",
    "state_scales",
    "state_size",
]


def split_states(effects, states):
    """The state vector of all effects (K,) → one array per effect."""
    out, k = [], 0
    for e in effects:
        m = len(e.state_names)
        out.append(states[k : k + m])
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


def rod_force(effects, states, rod):
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


def rates(effects, states, instant):
    parts = [
        jnp.asarray(e.rates(instant, s), float) for e, s in zip(effects, split_states(effects, states)) if e.state_names
    ]
    return jnp.concatenate(parts) if parts else jnp.zeros(0)
