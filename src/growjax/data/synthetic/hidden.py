"""The hidden effect of a synthetic experiment: an effect by name at a size, and the parameters that carry it."""

from __future__ import annotations

import dataclasses

import growjax as gj
from growjax.model import effects as fx
from growjax.model.effects import Effect

from .outside import OUTSIDE

__all__ = [
    "effect_class",
    "hidden_effect_parameters",
    "known_effects",
    "magnitude_field",
    "make_effect",
    "moderate_magnitude",
]


def known_effects() -> dict:
    """Name → class of every effect a synthetic experiment can hide: the catalogue (with registered effects), then
    `OUTSIDE`."""
    return {**fx.CATALOGUE, **OUTSIDE}


def effect_class(name: str) -> type[Effect]:
    """The effect class named ``name`` (the catalogue's, registered ones included, or `OUTSIDE`'s).

    Raises:
        ValueError: an unknown name.
    """
    known = known_effects()
    if name not in known:
        raise ValueError(f"unknown effect {name!r}; known: {sorted(known)}")
    return known[name]


def magnitude_field(effect) -> str:
    """The field of an effect (name, class or instance) that `make_effect`'s magnitude sets (its first)."""
    cls = effect_class(effect) if isinstance(effect, str) else (effect if isinstance(effect, type) else type(effect))
    return cls.magnitude_field()


def moderate_magnitude(effect: str) -> float:
    """The moderate magnitude of ``effect`` (SI, the unit of its `magnitude_field`): its class's ``moderate``."""
    return float(effect_class(effect).moderate)


def make_effect(effect: str, magnitude: float | None = None) -> Effect:
    """An instance of the named effect with its magnitude field set (default `moderate_magnitude`).

    Raises:
        ValueError: an unknown effect, or a magnitude outside the effect's physical range.
    """
    return effect_class(effect).at(magnitude)


def hidden_effect_parameters(effect: Effect | None = None, base=None, *, superset: bool = True, drive: str = "forward"):
    """``base`` (default `growjax.reference` for ``drive``) with ``effect`` switched on.

    With ``superset`` (default) every effect of `known_effects` is present,
    at zero (absent) except ``effect`` and any effect ``base`` already carries, in one fixed order:
    the same model, and one pytree structure for every hidden effect, so all of them share one
    compiled solver per configuration (the reference's compilation takes about a minute). The zero
    effects add states with zero rates only: the solution differs from the effect-alone model at the
    solver's tolerance.
    """
    base = gj.reference(drive) if base is None else base
    if not superset:
        return base if effect is None else gj.with_effects(base, effect)
    given = {e.name: e for e in base.effects}
    if effect is not None:
        given[effect.name] = effect
    ordered = [given.pop(name, cls()) for name, cls in known_effects().items()]
    return dataclasses.replace(base, effects=tuple(ordered) + tuple(given.values()))
