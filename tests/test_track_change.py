"""Change detection (growjax.track.watch) on records the reference configuration made: a leak opening at a drawn time
is flagged soon after and named a leak; a clean record raises no flag.

The records (``growjax/data/datasets/track``, ``data/make_track.py``): ``leak``, 3 s of the published pulse on a
drawn rig with a leak of 2e-13 m³/(s·Pa) opening at a time drawn in 1.2–2.4 s; ``rig0``, 3 s on another drawn rig,
nothing changing. Every test here shares one compiled filter (the watch model of the command line's default; the
records, of one length, share it).
"""

import json

import numpy as np
import pytest
from conftest import DATASETS

import growjax as gj
from growjax import track as tk
from growjax.data import experiment as ex
from growjax.track import change as ch

TRACK = DATASETS / "track"


def record(name):
    path = TRACK / f"{name}.csv"
    return ex.read(path), json.loads(path.with_suffix(".json").read_text())


@pytest.fixture(scope="module")
def model():
    return tk.state_space(gj.reference("forward"), sensors=tk.sensor_set("pressure,syringe"), estimate=("Y",))


@pytest.fixture(scope="module")
def leak(model):
    exp, meta = record("leak")
    return tk.watch(exp, model), meta


def test_a_leak_opening_is_flagged_within_half_a_second_and_named(leak):
    watched, meta = leak
    at = meta["switch"]["at_s"]
    assert len(watched.changes) == 1
    change = watched.changes[0]
    assert at <= change.flagged_s <= at + 0.5  # never before it opens
    assert change.effect == "leak" and change.parameter == "fluid_leak.conductance"
    assert change.evidence["leak"] == max(change.evidence.values())
    assert abs(change.onset_s - at) < 0.3
    truth = meta["switch"]["values"]["fluid_leak.conductance"]
    assert 0.3 * truth < change.estimate < 3 * truth  # its size, roughly, from a few tenths of a second
    assert watched.flags().sum() == 1 and watched.statistic.max() > ch.Cusum().threshold
    assert watched.dismissed == ()


def test_after_the_flag_the_leak_is_tracked_in_the_state(leak):
    watched, meta = leak
    est, lo, hi = watched.track.band("fluid_leak.conductance_m3_s_Pa")
    t = watched.track.time
    before = t < watched.changes[0].onset_s
    assert np.all(est[before] == 0) and np.all(hi[before] == lo[before])  # absent until flagged
    truth = meta["switch"]["values"]["fluid_leak.conductance"]
    assert lo[-1] < truth < hi[-1]


def test_a_clean_record_raises_no_flag(model):
    exp, _ = record("rig0")
    watched = tk.watch(exp, model)
    assert watched.changes == () and watched.dismissed == () and watched.flags().sum() == 0
    assert watched.statistic.max() < 0.8 * ch.Cusum().threshold  # not a near miss


def test_the_watch_model_carries_the_candidates_absent(model):
    wmodel = tk.watch_model(model)
    names = [p.name for p in wmodel.parameters]
    assert names[: len(tk.CANDIDATES)] == [c.parameter for c in tk.CANDIDATES]
    belief = ch.absent(ch.Belief(0.0, *wmodel.initial()), [ch.candidate_index(wmodel, c) for c in tk.CANDIDATES])
    for c in tk.CANDIDATES:
        i = ch.candidate_index(wmodel, c)
        assert belief.mean[i] == 0 and np.all(belief.cov[i] == 0) and np.all(belief.cov[:, i] == 0)
    with pytest.raises(ValueError, match="on in the model already"):
        tk.watch_model(tk.state_space(gj.with_effects(gj.reference("forward"), gj.effects.FluidLeak(1e-13))))
    with pytest.raises(ValueError, match="scale of the candidate"):
        tk.Candidate("leak", gj.effects.FluidLeak(), "fluid_leak.conductance", 0.0)


def test_a_hypothesis_under_which_the_solver_fails_is_not_named_and_does_not_stop_the_watch(monkeypatch):
    """The naming bank runs each hypothesis from the onset; one whose trial fails in the solver (a candidate driven
    out of its physical range: trapped air below none) gets evidence −∞ and is passed over; where every one fails,
    the watch stops with the reason. No model is compiled: the steps are stand-ins."""
    n = len(tk.CANDIDATES)
    index = list(range(n))
    start = ch.Belief(0.0, np.zeros(n), np.zeros((n, n)))
    trial_ll = {"leak": -5.0, "tip load": -1.0, "fold": -9.0}  # per step; trapped air fails

    class Step:
        def __init__(self, ll):
            self.log_likelihood = ll

    def step(run, belief, t, y, inputs, breaks, previous):
        opened = [c.name for c, i in zip(tk.CANDIDATES, index) if belief.cov[i, i] > 0]
        if opened == ["trapped air"] or run == "all fail":
            raise RuntimeError(f"the solver failed between {previous:.3f} s and {t:.3f} s")
        return belief, Step(trial_ll.get(opened[0], -20.0) if opened else -20.0)

    monkeypatch.setattr(ch, "checked_step", step)
    times = np.arange(6) * 0.01
    fields, path = ch.name_change(start, tk.CANDIDATES, index, ("run", times, times, None, None, 0, 5))
    assert fields["effect"] == "tip load" and len(path) == 5
    assert fields["evidence"]["trapped air"] == -np.inf and fields["evidence"]["tip load"] == -5.0
    change = ch.Change(0.0, 0.01, 0.05, "pressure_Pa", **fields)
    assert json.loads(json.dumps(change.as_dict()))["evidence"]["trapped air"] is None
    with pytest.raises(RuntimeError, match="under every candidate"):
        ch.name_change(start, tk.CANDIDATES, index, ("all fail", times, times, None, None, 0, 5))


def test_a_flag_whose_effect_is_a_small_share_of_its_typical_size_is_dismissed(model, leak):
    """A change is reported only where its named effect is at least ``smallest`` (a tenth) of its candidate's scale:
    a 0.3 N tip load or a 2e-13 m³/(s·Pa) leak are; the faint tip load (8 mN) or trapped air (1.3e-4) that the
    fast configuration's own error over a clean minute reads as one are not. A bad ``smallest`` is refused before
    anything compiles."""
    by_name = {c.name: c for c in tk.CANDIDATES}

    def change(effect, estimate):
        return ch.Change(1.0, 1.5, 1.8, "syringe_displacement_m", effect, by_name[effect].parameter, estimate, 0.0, {})

    assert ch.material(change("tip load", 0.3), by_name["tip load"], 0.1)
    assert ch.material(change("leak", 2e-13), by_name["leak"], 0.1)
    assert not ch.material(change("tip load", 7.8e-3), by_name["tip load"], 0.1)
    assert not ch.material(change("trapped air", 1.3e-4), by_name["trapped air"], 0.1)
    assert ch.material(change("trapped air", 1.3e-4), by_name["trapped air"], 0.0)  # 0: every flag is a change
    # the watch sets such a flag aside and reads on as after a change: the leak, held to a hundred times its scale
    exp, _ = record("leak")
    strict = tk.watch(exp, model, smallest=100.0)
    assert strict.changes == () and strict.flags().sum() == 0
    assert [(c.effect, c.flagged_s) for c in strict.dismissed] == [("leak", leak[0].changes[0].flagged_s)]
    np.testing.assert_allclose(strict.track.band("robot_length_m")[0], leak[0].track.band("robot_length_m")[0])
    exp, _ = record("rig0")
    for bad in (-0.1, float("nan")):
        with pytest.raises(ValueError, match="smallest must be"):
            tk.watch(exp, model, smallest=bad)


def test_the_track_command_reports_the_change(tmp_path, leak):
    from growjax.cli import main

    out, summary = tmp_path / "out", tmp_path / "s.json"
    assert main(["track", str(TRACK / "leak.csv"), "--watch", "--out", str(out), "--json", str(summary)]) == 0
    changes = json.loads(summary.read_text())["changes"]
    assert [c["effect"] for c in changes] == ["leak"]
    assert changes[0]["flagged_s"] == pytest.approx(leak[0].changes[0].flagged_s)
    table = np.genfromtxt(out / "track.csv", delimiter=",", names=True)
    assert table["change_flag"].sum() == 1 and table["change_flag"][table["time_s"] < changes[0]["onset_s"]].sum() == 0
    assert "fluid_leakconductance_m3_s_Pa" in table.dtype.names  # the leak's estimate and band (genfromtxt drops '.')
    assert main(["track", str(TRACK / "leak.csv"), "--watch", "--smooth", "--out", str(out)]) == 2
