"""The noise-free reference solve behind a synthetic experiment, cached in memory per its arguments."""

from __future__ import annotations

import collections

import jax
import numpy as np

import growjax as gj
from growjax.hashing import content_key
from growjax.model.effects import Effect

from .hidden import hidden_effect_parameters, magnitude_field, make_effect
from .inputs import resolve_inputs

__all__ = ["CACHE_SIZE", "clear_cache", "noise_free", "reference_solve"]

_CACHE: collections.OrderedDict = collections.OrderedDict()
CACHE_SIZE = 64


def clear_cache() -> None:
    """Forget the cached noise-free reference solves."""
    _CACHE.clear()


def _effect_spec(effect, magnitude):
    """(Effect instance or None, name, magnitude or None) from the arguments of `make_experiment`."""
    if effect is None:
        if magnitude not in (None, 0, 0.0):
            raise ValueError("a magnitude was given without an effect")
        return None, None, None
    if isinstance(effect, Effect):
        if magnitude is not None:
            raise ValueError("give either an Effect instance or an effect name with a magnitude, not both")
        field = magnitude_field(effect)
        return effect, effect.name, float(getattr(effect, field))
    instance = make_effect(effect, magnitude)
    return instance, effect, float(getattr(instance, magnitude_field(instance)))


def reference_solve(params, model_inputs, config: gj.Config, ts) -> gj.Trajectory:
    """The one solve of the generator (``config`` is always the reference configuration)."""
    assert config.fidelity == "reference"
    return gj.simulate(params, model_inputs, config, ts=ts)


def noise_free(
    effect=None,
    magnitude: float | None = None,
    *,
    drive: str = "forward",
    inputs="public",
    t_end: float = 10.0,
    base=None,
    dt: float = 0.01,
    rtol: float = 1e-6,
    superset: bool = True,
) -> dict:
    """The noise-free reference solve behind `make_experiment` (cached; same arguments).

    Returns {"time": (T,) s, "length": m, "pressure": Pa, "columns": input columns, "inputs": description,
    "effect": Effect or None, "name", "magnitude", "status"}. Raises RuntimeError if the reference
    solver fails or the run crosses the membrane pressure limit.
    """
    instance, name, magnitude = _effect_spec(effect, magnitude)
    base_params = gj.reference(drive) if base is None else base
    inputs_key = inputs if isinstance(inputs, str) else ("inputs", content_key(inputs))
    key = (
        None if instance is None else (type(instance).__qualname__, content_key(instance)),
        drive,
        inputs_key,
        round(float(t_end), 9),
        float(dt),
        float(rtol),
        bool(superset),
        None if base is None else (content_key(base), str(jax.tree_util.tree_structure(base))),
    )
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    model_inputs, time, cols, description = resolve_inputs(inputs, drive, base_params, t_end, dt)
    params = hidden_effect_parameters(instance, base_params, superset=superset)
    config = gj.Config(fidelity="reference", drive=drive, t1=float(time[-1]), rtol=rtol, atol=rtol)
    ts = np.concatenate([[config.t0], time]) if time[0] > config.t0 else time
    traj = reference_solve(params, model_inputs, config, ts)
    status = int(traj.status)
    if status != gj.OK:
        raise RuntimeError(
            f"the reference solve with {name or 'no effect'} (magnitude {magnitude}) ended with "
            f"status {gj.status_name(status)} at t = {float(traj.t_final):.3f} s"
        )
    offset = ts.size - time.size
    out = {
        "time": time,
        "length": np.asarray(traj.length)[offset:],
        "pressure": np.asarray(traj.pressure)[offset:],
        "syringe_displacement": np.asarray(traj.syringe_displacement)[offset:],
        "robot_flow": np.asarray(traj.robot_flow)[offset:],
        "columns": cols,
        "inputs": description,
        "effect": instance,
        "name": name,
        "magnitude": magnitude,
        "status": gj.status_name(status),
        "rtol": rtol,
    }
    _CACHE[key] = out
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return out
