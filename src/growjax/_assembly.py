"""What both assemblies share about their state: its layout (base states, then effect states) and the scaled field."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from growjax import effects as fx


def layout(params, drive: str, forward: tuple, inverse: tuple) -> tuple[tuple, tuple]:
    """(state names, scales) for ``drive``: the assembly's base ``(names, scales)`` pair, effect states last."""
    names, scales = forward if drive == "forward" else inverse
    extra = tuple(f"{e.name}.{s}" for e in params.effects for s in e.state_names)
    return names + extra, scales + fx.state_scales(params.effects, drive)


def vector_fields(forward_rates, inverse_rates, layout_of):
    """(rates, vector_field) of an assembly from its per-drive rate functions.

    ``rates(t, y, params, inputs, config, prep)`` → (unscaled rates, outputs) for ``config.drive``;
    ``vector_field(t, ys, args)`` is the scaled field diffrax integrates, ``args`` = (params, inputs, config, prep).
    """

    traced = {"forward": eqx.filter_jit(forward_rates), "inverse": eqx.filter_jit(inverse_rates)}

    def rates(t, y, params, inputs, config, prep):
        return traced[config.drive](t, y, params, inputs, config, prep)

    def vector_field(t, ys, args):
        params, inputs, config, prep = args
        scales = jnp.asarray(layout_of(params, config.drive)[1])
        return rates(t, ys * scales, params, inputs, config, prep)[0] / scales

    return rates, vector_field
