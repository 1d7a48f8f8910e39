"""An effect of one's own joins the catalogue through growjax.model.effects.register, with its declaration checked."""

from typing import ClassVar

import jax.numpy as jnp
import pytest

import growjax as gj
from growjax import discover as gd
from growjax.model import effects as fx


def _effect(name, ranges, units):
    return type(
        "Custom",
        (fx.Effect,),
        {
            "__annotations__": {
                "name": ClassVar[str],
                "description": ClassVar[str],
                "units": ClassVar[dict],
                "ranges": ClassVar[dict],
                "stiffness": float,
            },
            "name": name,
            "description": "pull proportional to the length",
            "units": units,
            "ranges": ranges,
            "stiffness": 0.0,
            "rod_force": lambda self, rod, state: self.stiffness * rod.length + jnp.zeros_like(rod.pressure),
        },
    )


def test_register_adds_a_candidate_and_checks_its_declaration(monkeypatch):
    monkeypatch.setattr(fx, "CATALOGUE", dict(fx.CATALOGUE))  # leave the shared catalogue as it was
    cls = fx.register(_effect("length_drag", {"stiffness": (0.0, 5.0)}, {"stiffness": "N/m"}))
    assert fx.CATALOGUE["length_drag"] is cls
    assert gd.candidate_parameter("length_drag") == ("length_drag.stiffness", "N/m", (0.0, 5.0))
    params = gj.with_effects(gj.reference(), cls(stiffness=1.0))
    assert float(gj.get(params, "length_drag.stiffness")) == 1.0
    with pytest.raises(ValueError, match="not in the catalogue"):
        fx.register(_effect("length_drag", {"stiffness": (0.0, 5.0)}, {"stiffness": "N/m"}))
    with pytest.raises(ValueError, match="one parameter"):
        fx.register(_effect("two", {"a": (0.0, 1.0), "b": (0.0, 1.0)}, {"a": "-", "b": "-"}))
    with pytest.raises(ValueError, match="includes 0"):
        fx.register(_effect("offset", {"stiffness": (1.0, 5.0)}, {"stiffness": "N/m"}))
    with pytest.raises(TypeError):
        fx.register(object)
