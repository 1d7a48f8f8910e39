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
    assert watched.changes == () and watched.flags().sum() == 0
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
