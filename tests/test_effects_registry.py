"""An effect of one's own joins the catalogue through growjax.model.effects.register, with its declaration checked,
and every workflow then takes it with no other edit: synthetic data hide it at its moderate size, discovery tests
it as a candidate, a discriminating design sizes it, `growjax effects` lists it."""

import json
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

import growjax as gj
from growjax import cli
from growjax import discover as gd
from growjax.calibration import discrepancy as dc
from growjax.data import synthetic as sy
from growjax.data.sets import ExperimentSet
from growjax.design import discrimination as ddis
from growjax.model import effects as fx

Y = "robot.yield_pressure"


class TetherDrag(fx.Effect):
    """A tether dragged along behind the robot: a pull F = k·L opposing growth (k in N/m; 0 = absent)."""

    name: ClassVar[str] = "tether_drag"
    description: ClassVar[str] = "pull k·L of a tether dragged along the everted length"
    units: ClassVar[dict] = {"stiffness": "N/m"}
    ranges: ClassVar[dict] = {"stiffness": (0.0, 5.0)}
    moderate: ClassVar[float] = 0.5
    separated_by: ClassVar[str] = "runs with the tether slack and taut (the pull scales with the everted length)"
    stiffness: float = 0.0

    def rod_force(self, rod, state):
        return self.stiffness * rod.length + jnp.zeros_like(rod.pressure)


@pytest.fixture
def registered():
    """`TetherDrag` in the catalogue for one test, taken out again after it."""
    fx.register(TetherDrag)
    yield TetherDrag
    fx.unregister(TetherDrag.name)


def _effect(name, ranges, units, moderate=1.0, separated_by="a measurement that tells it apart"):
    return type(
        "Custom",
        (fx.Effect,),
        {
            "__annotations__": {
                "name": ClassVar[str],
                "description": ClassVar[str],
                "units": ClassVar[dict],
                "ranges": ClassVar[dict],
                "moderate": ClassVar[float],
                "separated_by": ClassVar[str],
                "stiffness": float,
            },
            "name": name,
            "description": "pull proportional to the length",
            "units": units,
            "ranges": ranges,
            "moderate": moderate,
            "separated_by": separated_by,
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
    stiffness = {"stiffness": (0.0, 5.0)}, {"stiffness": "N/m"}
    for bad, message in (
        (_effect("length_drag", *stiffness), "not in the catalogue"),
        (_effect("two", {"a": (0.0, 1.0), "b": (0.0, 1.0)}, {"a": "-", "b": "-"}), "one parameter"),
        (_effect("offset", {"stiffness": (1.0, 5.0)}, {"stiffness": "N/m"}), "includes 0"),
        (_effect("unsized", *stiffness, moderate=0.0), "moderate"),
        (_effect("oversized", *stiffness, moderate=6.0), "moderate"),
        (_effect("unseparated", *stiffness, separated_by=""), "separated_by"),
    ):
        with pytest.raises(ValueError, match=message):
            fx.register(bad)
    with pytest.raises(TypeError):
        fx.register(object)
    with pytest.raises(ValueError, match="not a registered effect"):
        fx.unregister("fluid_leak")  # the package's own effects stay
    assert fx.unregister("length_drag") is cls and "length_drag" not in fx.CATALOGUE


def test_a_registered_effect_is_sized_listed_and_reported_by_every_workflow(registered, capsys):
    """With no edit elsewhere: synthetic data's effect at its moderate size (and its range checked), the superset
    of hidden effects, the discovery's candidate and its separating measurement, a discriminating design's rival
    sizes, and the catalogue command."""
    assert sy.make_effect("tether_drag") == TetherDrag(stiffness=0.5) and sy.moderate_magnitude("tether_drag") == 0.5
    with pytest.raises(ValueError, match="outside its range"):
        sy.make_effect("tether_drag", 7.0)
    assert "tether_drag" in sy.known_effects()
    hidden = sy.hidden_effect_parameters(TetherDrag(stiffness=0.2))
    assert [type(e) for e in hidden.effects].count(TetherDrag) == 1
    assert float(gj.get(hidden, "tether_drag.stiffness")) == 0.2
    assert gd.candidate_parameter("tether_drag") == ("tether_drag.stiffness", "N/m", (0.0, 5.0))
    assert ddis.checked_pair(("tether_drag", "active_channel_force")) == (
        ("tether_drag", "active_channel_force"),
        (0.5, fx.ActiveChannelForce.moderate),
    )
    with pytest.raises(ValueError, match="outside its range"):
        ddis.checked_pair(("tether_drag", "active_channel_force"), (9.0, 0.01))
    assert cli.main(["effects", "--json", "-"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)["effects"]}
    assert rows["tether_drag"]["separated_by"] == TetherDrag.separated_by
    assert rows["tether_drag"]["parameter"] == "tether_drag.stiffness" and rows["tether_drag"]["range"] == [0.0, 5.0]


def _knowledge(base):
    """The short case of tests/test_design_discrimination.py: Y known to 3 %, two toleranced rig parameters."""
    from growjax import design

    return design.Knowledge(
        base,
        (Y,),
        np.array([[0.03**2]]),
        {"robot.catheter_friction": 0.2, "pid.proportional": 0.05},
        dc.Hyper.of(1e-4, 0.8, 2e-4, 0.01),
        "test",
    )


@pytest.mark.slow
def test_a_registered_effect_is_hidden_in_synthetic_data_found_by_discovery_and_discriminated(registered):
    """A tether drag at its moderate size hidden by the reference configuration (1.5 s, the shipped inputs): it
    shortens the robot by clearly more than the noise; discovery against it and a leak names it, the interval of
    its size covering the truth; and a discriminating design's T separates it from the active channel's pull."""
    from growjax import design

    t_end = 1.5
    clean = sy.noise_free(None, drive="forward", inputs="synthetic", t_end=t_end, superset=False)
    exp = sy.make_experiment("tether_drag", seed=11, inputs="synthetic", t_end=t_end, superset=False)
    assert exp.metadata["magnitude"] == 0.5 and exp.metadata["in_catalogue"]
    shortening = (
        clean["length"][-1]
        - sy.noise_free("tether_drag", inputs="synthetic", t_end=t_end, superset=False)["length"][-1]
    )
    assert shortening > 5 * exp.metadata["noise_sd"]["robot_length_m"]
    res = gd.discover(
        ExperimentSet.single(exp, sensors=("length",)),
        config=gj.Config(t1=t_end),
        candidates=("tether_drag", "fluid_leak"),
        workers=1,
    )
    assert "tether_drag" in res.evidence[0]
    assert res.effect == "tether_drag", gd.summary_text(res)
    lo, hi = res.parameters["tether_drag.stiffness"]["interval_90"]
    assert lo <= 0.5 <= hi
    base = gj.replace(gj.reference("forward"), Y=9000.0)
    catheter = gj.Sampled(jnp.asarray([0.0, 10.0]), jnp.asarray([0.004, 0.044]))
    space = design.DesignSpace(1.0, 336e3, catheter, knot_spacing=0.5)
    problem = ddis.make(_knowledge(base), space, ("tether_drag", "active_channel_force"))
    np.testing.assert_allclose(problem.sizes, [[0.5, 0.0], [0.0, 0.01]])
    x = np.zeros(len(space.knots) - 1)
    t_ab, t_ba = map(float, ddis.statistics(problem, problem.inputs(x), problem.breaks))
    assert t_ab > 0.0 and t_ba > 0.0
