"""Discovery over an experiment set: its threshold, its refusals of bad input, and (slow) its verdicts on
reference-made sets, with and without a hidden effect."""

import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import growjax as gj
from growjax import calibration as cal
from growjax import cli
from growjax import discover as gd
from growjax.calibration import likelihood_ratio as lrt
from growjax.data import experiment as ex
from growjax.data import sets as xs

DISCOVERY_SET = Path(str(files("growjax.data") / "datasets" / "discovery_set"))
CLEAN_SET = Path(str(files("growjax.data") / "datasets" / "set"))
CANDIDATES = ("retraction_folding", "fluid_leak", "active_channel_force")
CONFIG = gj.Config(t1=3.0)


def test_the_threshold_is_the_single_rule_for_one_robot_and_holds_its_rate_for_several():
    """One copy: ½χ²₀ + ½χ²₁ at the Bonferroni share, the single experiment's rule. Several copies (one per robot):
    the boundary mixture, whose false-alarm rate at the threshold matches draws of Σ max(0, Z)²."""
    assert lrt.boundary_threshold(0.05 / 3) == pytest.approx(stats.chi2.isf(2 * 0.05 / 3, df=1), rel=1e-12)
    rng = np.random.default_rng(20261126)
    for copies in (2, 3):
        c = lrt.boundary_threshold(0.01, copies)
        assert lrt.boundary_p_value(c, copies) == pytest.approx(0.01, rel=1e-6)
        draws = np.sum(np.clip(rng.standard_normal((400_000, copies)), 0.0, None) ** 2, axis=1)
        assert np.mean(draws > c) == pytest.approx(0.01, rel=0.08)
        assert c > lrt.boundary_threshold(0.01, copies - 1)
    assert lrt.boundary_p_value(0.0, 2) == 1.0


def test_bad_input_is_refused_before_any_fit():
    exps = xs.read([DISCOVERY_SET / "set.toml"])
    with pytest.raises(ValueError, match="unknown effect 'folding'"):
        gd.discover(exps, candidates=["retraction_folding", "folding"])
    with pytest.raises(ValueError, match="named twice"):
        gd.discover(exps, candidates=["fluid_leak", "fluid_leak"])
    with pytest.raises(ValueError, match="effect_scope"):
        gd.discover(exps, candidates=["fluid_leak"], effect_scope="membrane")
    with pytest.raises(ValueError, match="false_positive_rate"):
        gd.discover(exps, candidates=["fluid_leak"], false_positive_rate=1.5)
    with pytest.raises(ValueError, match="unknown parameter 'Q'"):
        gd.discover(exps, candidates=["fluid_leak"], base_free=["Q@robot"])


def test_the_command_line_refuses_a_bad_set_or_effect_with_exit_2_and_one_line(tmp_path, capsys):
    manifest = DISCOVERY_SET / "set.toml"
    for argv, message in (
        ([str(manifest), "--candidates", "folding"], "unknown effect 'folding'"),
        ([str(manifest), str(manifest)], "give it alone"),
        ([str(DISCOVERY_SET / "pulse_slow.csv"), str(tmp_path / "absent.csv")], "not found"),
    ):
        try:
            code = cli.main(["discover", *argv, "--out", str(tmp_path / "out")])
        except SystemExit as stop:  # the parser's refusal
            code = stop.code
        assert code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err


@pytest.fixture(scope="module")
def folding_set():
    exps = xs.read([DISCOVERY_SET / "set.toml"])
    truth = json.loads((DISCOVERY_SET / "pulse_slow.json").read_text())
    return exps, truth, gd.discover(exps, config=CONFIG, candidates=CANDIDATES)


@pytest.mark.slow
def test_the_set_names_a_folding_that_no_experiment_alone_can(folding_set):
    """A small retraction folding hidden by the reference configuration in three short runs of one robot: each run
    alone (single-experiment discovery) leaves it under the threshold and names nothing; the set's joint fits name it, their 2ΔlogL above every run's, its size's
    90 % interval covering the truth, and no structure left in any run's residuals."""
    exps, truth, together = folding_set
    assert together.effect == "retraction_folding", gd.set_summary_text(together)
    label = f"{truth['parameter']}@membrane-1"
    lo, hi = together.parameters[label]["interval_90"]
    assert lo <= truth["magnitude"] <= hi
    lr_set = together.evidence[0]["retraction_folding"]["lr_statistic"]
    for run in exps.runs:  # a set of one takes single-experiment discovery
        alone = gd.discover(xs.ExperimentSet((run,)), config=CONFIG, candidates=CANDIDATES, workers=1)
        assert alone.effect == "none", (run.name, gd.summary_text(alone))
        assert alone.evidence[0]["retraction_folding"]["lr_statistic"] < min(alone.threshold, lr_set)
    assert not together.misfit_after["structured"]
    assert all(r["rmse_after_m"] < 1.2 * truth["noise_sd"]["robot_length_m"] for r in together.runs)
    assert not together.confounded_with and together.fits == 1 + len(CANDIDATES)


@pytest.mark.slow
def test_no_effect_is_named_on_a_clean_set_on_a_rig_off_its_nominal_values():
    """The shipped set (three demands, one robot, the rig drawn from its tolerances, no effect): no candidate clears
    the threshold, and the answer is none."""
    runs = xs.read([CLEAN_SET / "set.toml"])
    exps = xs.ExperimentSet(
        tuple(xs.Run(r.name, r.experiment.window(CONFIG.t1 + 1e-9), robot=r.robot, rig=r.rig) for r in runs)
    )  # the length alone, 3 s: the folding set's programs serve it
    res = gd.discover(exps, config=CONFIG, candidates=CANDIDATES)
    assert res.effect == "none", gd.set_summary_text(res)
    assert not any(s["clears_threshold"] for s in res.evidence[0].values())
    assert not res.effects and not res.confounded_with


# -- less trapped air than nominal: a signed effect found below zero, by one record and by two ----------------

LESS_AIR = -0.003  # the trapped-air effect's extra air fraction: α 0.005 → 0.002
AIR_CANDIDATES = ("trapped_air", "active_channel_force")


def _less_air(amplitude: float, seed: int, fidelity: str) -> xs.Run:
    """A 2 s run made by the ``fidelity`` configuration under a pulse train of ``amplitude`` Pa (catheter 4 mm) with
    less air than nominal (`LESS_AIR`), its length with 0.2 mm of seeded noise, as a run with the inputs it ran."""
    inputs = gj.Inputs(catheter_length=gj.Constant(0.004), pressure_demand=gj.PulseTrain(amplitude=amplitude))
    made = gj.with_effects(gj.reference(), gj.effects.TrappedAir(extra_fraction=LESS_AIR))
    times = np.round(np.arange(1, 201) * 0.01, 10)
    traj = gj.simulate(made, inputs, gj.Config(fidelity=fidelity, t1=2.0), ts=times)
    noisy = np.asarray(traj.length) + np.random.default_rng(seed).normal(0.0, 2e-4, times.size)
    return xs.Run(f"pulse {amplitude / 1e3:.0f} kPa", ex.from_arrays(times, noisy), inputs=inputs)


def _names_less_air(res) -> list[float]:
    """The estimates of the extra air fraction (one per copy) of a discovery that names trapped air below zero with
    every 90 % interval covering the truth."""
    text = gd.summary_text(res) if isinstance(res, gd.DiscoveryResult) else gd.set_summary_text(res)
    assert res.effect == "trapped_air", text
    sizes = {k: p for k, p in res.parameters.items() if k.startswith("trapped_air.extra_fraction")}
    assert sizes, text
    for p in sizes.values():
        lo, hi = p["interval_90"]
        assert p["estimate"] < 0.0 and lo <= LESS_AIR <= hi, text
    return [p["estimate"] for p in sizes.values()]


@pytest.mark.slow
def test_less_trapped_air_than_nominal_is_named_below_zero_from_one_reference_made_record_and_from_two():
    """Records made by the reference configuration with less air than nominal: single-experiment discovery (a set
    of one) and the set's joint fits (two records, one robot) agree, each naming trapped air with a negative
    extra fraction whose 90 % interval covers the truth."""
    runs = (_less_air(150e3, 1, "reference"), _less_air(100e3, 2, "reference"))
    one = gd.discover(xs.ExperimentSet(runs[:1]), config=gj.Config(t1=2.0), candidates=AIR_CANDIDATES, workers=1)
    assert isinstance(one, gd.DiscoveryResult)
    two = gd.discover(xs.ExperimentSet(runs), config=gj.Config(t1=2.0), candidates=AIR_CANDIDATES)
    assert isinstance(two, gd.SetDiscoveryResult)
    _names_less_air(one)
    _names_less_air(two)


def test_less_trapped_air_than_nominal_is_named_below_zero_by_a_set_of_one_and_by_a_set_of_two():
    """The cheap companion: records made by the fast configuration, trapped air the one candidate, independent noise
    and the rig taken as known. A set of one (the single-experiment path) and a set of two (the joint fits, whose
    trapped air moves in a linear coordinate over its signed range) both name it below zero, covering the truth."""
    runs = (_less_air(150e3, 1, "fast"), _less_air(100e3, 2, "fast"))
    options = dict(
        config=gj.Config(t1=2.0),
        candidates=("trapped_air",),
        likelihood=cal.Likelihood(discrepancy="none", tolerances={}),
    )
    (alone,) = _names_less_air(gd.discover(xs.ExperimentSet(runs[:1]), multistart=False, workers=1, **options))
    (both,) = _names_less_air(gd.discover(xs.ExperimentSet(runs), scout=0, **options))
    assert both == pytest.approx(alone, abs=0.001)
