"""Tracking: the calibrated model as a live estimator (growjax.track) on records the reference configuration made.

The records (``growjax/data/datasets/track``, ``data/make_track.py``): 3 s of the published pulse on rigs drawn from
the default tolerance budget, and one whose Y drifts. The filter reads the pump's own sensors (pressure 0.5 kPa,
syringe 5 µm) and runs the fast configuration; every test here shares one compiled filter (one model), so the
file pays for one compile.
"""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import DATASETS
from scipy.stats import chi2

import growjax as gj
from growjax import track as tk
from growjax.data import experiment as ex
from growjax.track import sensors as ts

TRACK = DATASETS / "track"
RIGS = ("rig0", "rig1", "rig2")


def record(name):
    """(experiment, sidecar) of a shipped tracking record."""
    path = TRACK / f"{name}.csv"
    return ex.read(path), json.loads(path.with_suffix(".json").read_text())


@pytest.fixture(scope="module")
def model():
    """The command line's default model: pressure and syringe, Y a random walk, the default tolerance budget."""
    return tk.state_space(gj.reference("forward"), sensors=ts.sensor_set("pressure,syringe"), estimate=("Y",))


@pytest.fixture(scope="module")
def tracked(model):
    """{record: (its filtered result, its sidecar)} of the drawn rigs."""
    out = {}
    for name in RIGS:
        exp, meta = record(name)
        out[name] = (tk.track(exp, model), meta)
    return out


def test_sensors_are_chosen_by_name_with_their_noise():
    chosen = ts.sensor_set("syringe,pressure", {"pressure": 800.0})
    assert [s.column for s in chosen] == ["pressure_Pa", "syringe_displacement_m"]
    assert chosen[0].noise == 800.0 and chosen[1].noise == 5e-6
    assert ts.parse_noise("pressure=500, syringe_displacement_m=1e-5") == {
        "pressure_Pa": 500.0,
        "syringe_displacement_m": 1e-5,
    }


@pytest.mark.parametrize(
    "names, noise, message",
    [
        ("pressure,camera", None, "unknown sensor 'camera'"),
        ("pressure,pressure_Pa", None, "chosen twice"),
        ("", None, "at least one sensor"),
        ("pressure", {"flow": 1e-9}, "not a chosen sensor"),
        ("pressure", {"pressure": -1.0}, "must be a positive number"),
    ],
)
def test_a_bad_sensor_choice_is_refused_in_one_line(names, noise, message):
    with pytest.raises(ValueError, match=message):
        ts.sensor_set(names, noise)


def test_the_pump_columns_are_read_with_their_units_checked(tmp_path):
    path = tmp_path / "pump.csv"
    t = np.array([0.01, 0.02, 0.03])
    ex.write_csv(path, t, {"catheter_length_m": t, "syringe_displacement_m": [0.0, -2e-6, 1e-5]})
    exp = ex.read(path)
    assert np.allclose(exp["syringe_displacement_m"], [0.0, -2e-6, 1e-5])  # noise about the full stop: negative
    ex.write_csv(path, t, {"catheter_length_m": t, "syringe_displacement_m": [0.0, 0.4, 750.0]})
    with pytest.raises(ex.ExperimentError, match="millimetres"):
        ex.read(path)
    ex.write_csv(path, t, {"catheter_length_m": t, "robot_flow_m3_s": [0.0, 40.0, 41.0]})
    with pytest.raises(ex.ExperimentError, match="mm³/s"):
        ex.read(path)
    ex.write_csv(path, t, {"catheter_length_m": t, "robot_length_m": [0.01, np.nan, np.nan]})  # read once
    with pytest.raises(ex.ExperimentError, match="NaN"):
        ex.read(path)
    sparse = ex.read(path, sparse=ex.MEASURED_COLUMNS)
    assert sparse["robot_length_m"][0] == 0.01 and np.all(np.isnan(sparse["robot_length_m"][1:]))


def test_a_missing_sensor_column_is_named(model):
    exp, _ = record("rig0")
    lean = ex.Experiment(exp.time, {"pressure_Pa": exp["pressure_Pa"], "catheter_length_m": exp["catheter_length_m"]})
    with pytest.raises(ValueError, match="no syringe_displacement_m column"):
        tk.track(lean, model)


def test_the_length_from_the_pump_alone_stays_in_its_band(tracked):
    """On rigs the filter does not know (their tolerances drawn), made by the configuration it does not run, the
    length the pump's sensors imply is within 0.2 mm, and its 90 % band holds the truth at most samples."""
    inside, total = 0, 0
    for result, meta in tracked.values():
        truth = np.asarray(meta["noise_free_length_m"])
        score = result.score(truth)
        assert score["rmse_m"] < 2e-4
        inside += score["coverage_90"] * score["samples"]
        total += score["samples"]
    assert 0.75 <= inside / total <= 1.0


def test_the_innovations_and_the_rig_errors_are_as_likely_as_the_filter_says(model, tracked):
    """NIS: the innovations' normalised squares average one per reading; NEES: the rig's relative errors at the end,
    normalised by the filter's covariance, are a χ² draw with one degree of freedom per toleranced parameter."""
    n = model.model_size
    rig = [i for i, p in enumerate(model.parameters) if p.tolerance]
    nees = 0.0
    for result, meta in tracked.values():
        assert 0.7 < result.consistency()["nis_per_reading"] < 1.4
        truth = np.log(
            [meta["rig"][model.parameters[i].name] / gj.get(model.params, model.parameters[i].name) for i in rig]
        )
        idx = n + np.array(rig)
        err = result.mean[-1, idx] - truth
        nees += err @ np.linalg.solve(result.cov[-1][np.ix_(idx, idx)], err)
    assert nees < chi2.ppf(0.995, len(rig) * len(RIGS))


def test_the_smoother_never_widens_a_band(model):
    exp, meta = record("rig1")
    filtered = tk.track(exp, model)
    smoothed = tk.track(exp, model, smooth=True)
    width = lambda r: np.subtract(*r.band("robot_length_m")[2:0:-1])  # noqa: E731
    assert np.all(width(smoothed) <= width(filtered) * (1 + 1e-9) + 1e-12)
    assert np.mean(width(smoothed)) < 0.9 * np.mean(width(filtered))
    truth = np.asarray(meta["noise_free_length_m"])
    assert smoothed.score(truth)["coverage_90"] >= 0.75


@pytest.mark.xfail(
    strict=True,
    reason="on the shipped drift record the walk of Y covers under half of the drift in 3 s; the benchmark's 60 s "
    "records (python benchmarks/track.py --drift 3) are the measure",
)
def test_a_random_walk_y_follows_a_drift(model):
    exp, meta = record("drift")
    values = np.asarray(meta["drift"]["values"])
    est, lo, hi = tk.track(exp, model).band("Y_Pa")
    start, end = values[0], values[-1]
    assert abs(est[-1] - end) < 0.5 * abs(end - start)  # moved most of the way
    assert lo[-1] <= end <= hi[-1]
    assert np.mean((values >= lo) & (values <= hi)) > 0.75


def test_one_program_serves_a_sensor_set_whatever_is_missing(model, tracked):
    """Every record, and a record whose pressure is missing at some samples and whose syringe reading stops, is
    tracked by the one program compiled for the sensor set."""
    exp, meta = record("rig2")
    pressure = np.array(exp["pressure_Pa"])
    syringe = np.array(exp["syringe_displacement_m"])
    pressure[::3] = np.nan
    syringe[200:] = np.nan
    gappy = ex.Experiment(exp.time, {**exp.series, "pressure_Pa": pressure, "syringe_displacement_m": syringe})
    before = tk.Filter(model).traces()  # the full records are tracked (``tracked``): their program is compiled
    result = tk.track(gappy, model)
    assert np.all(np.isfinite(result.band("robot_length_m")[0]))
    assert np.array_equal(result.dof, np.isfinite(pressure).astype(int) + np.isfinite(syringe))
    assert tk.Filter(model).traces() == before  # none traced for the gaps (a count of this test's own, whatever ran
    # before it in this process: the output-feedback loop steps the same filter with inputs of its own)
    full = tracked["rig2"][0]
    width = lambda r: np.subtract(*r.band("robot_length_m")[2:0:-1])  # noqa: E731
    assert np.mean(width(result)[200:]) > np.mean(width(full)[200:])  # less read, less known


def test_the_track_command_writes_the_bands_and_scores_the_unread_length(tmp_path):
    """Without DATA the command reads the shipped record of the pump's sensors (the synthetic experiment, every
    other command's default, has no syringe column)."""
    from growjax.cli import main

    out = tmp_path / "out"
    assert main(["track", "--t-end", "3", "--out", str(out), "--json", str(tmp_path / "s.json")]) == 0
    header = (out / "track.csv").read_text().splitlines()[0].split(",")
    for stem, unit in (("robot_length", "m"), ("pressure", "Pa"), ("Y", "Pa")):
        assert {f"{stem}_{unit}", f"{stem}_lower_{unit}", f"{stem}_upper_{unit}"} <= set(header)
    assert header[0] == "time_s" and "measured_robot_length_m" in header
    summary = json.loads((tmp_path / "s.json").read_text())
    assert Path(summary["data"]).resolve() == (TRACK / "rig0.csv").resolve()
    assert summary["score"]["samples"] == 300 and summary["score"]["rmse_m"] < 1e-3  # 0.2 mm noise on the truth
    # a reading falls in the band widened by the length sensor's noise (0.2 mm, its default): 0.91 here, 0.47
    # against the band of the true length alone
    assert summary["score"]["noise_m"] == 2e-4 and summary["score"]["coverage_90"] > 0.8
    assert (out / "track.png").is_file()


def test_a_bad_option_of_the_track_command_is_one_line(tmp_path, capsys):
    from growjax.cli import main

    data = str(TRACK / "rig0.csv")
    assert main(["track", data, "--sensors", "pressure,sonar", "--out", str(tmp_path)]) == 2
    assert "unknown sensor 'sonar'" in capsys.readouterr().err
    assert main(["track", data, "--estimate", "Q", "--out", str(tmp_path)]) == 2
    assert "unknown parameter 'Q'" in capsys.readouterr().err


@pytest.mark.slow
def test_an_unrecorded_demand_is_estimated_where_it_is_known():
    """With the demand in the state (a random walk), the pump's sensors recover the published pulse train that made
    the record: high while it is on, low while it is off, the truth inside the band at most samples."""
    exp, _ = record("rig0")
    model = tk.state_space(
        gj.reference("forward"),
        sensors=ts.sensor_set("pressure,syringe"),
        estimate=("Y",),
        inputs=(tk.InputState("pressure_demand"),),
    )
    result = tk.track(exp, model, smooth=True)
    est, lo, hi = result.band("pressure_demand_Pa")
    truth = np.asarray(jax.vmap(gj.published_pulse())(exp.time))
    on, off = truth > 0, truth == 0
    assert np.median(est[on]) > 120e3 and np.median(est[off]) < 30e3
    assert np.mean((truth >= lo) & (truth <= hi)) > 0.7


def test_a_steep_transition_carries_the_covariance_without_negative_variances():
    from growjax.track.belief import square_root

    rng = np.random.default_rng(3)
    basis = np.linalg.qr(rng.standard_normal((4, 4)))[0]
    values = np.array([-1e-21, 1e-20, 1e-6, 1.0])  # rounding's negative eigenvalue beside tiny ones
    cov = np.zeros((5, 5))
    cov[:4, :4] = (basis * values) @ basis.T  # the last coordinate has no variance (an effect absent)
    root = np.asarray(square_root(cov))
    np.testing.assert_allclose(root @ root.T, cov - values[0] * np.outer(*[np.append(basis[:, 0], 0)] * 2), atol=1e-15)
    assert np.all(root[4] == 0.0)
    jac = np.eye(5)
    jac[:4, :4] += 1e14 * np.outer(basis[:, 0], basis[:, 0])  # a sharp switch's Jacobian along that direction
    assert np.linalg.eigvalsh(jac @ cov @ jac.T).min() < -1.0  # carried directly: a negative variance
    carried = (jac @ root) @ (jac @ root).T
    assert np.linalg.eigvalsh(carried).min() >= -1e-12 * np.abs(carried).max()
    assert np.all(carried[4] == 0.0)


# A state the filter reached at the end of a pulse's off phase (SI, the model's states then ln Y and the rig's six
# toleranced parameters): the chamber just below the robot's pressure, the robot retracting through the bypass.
RETRACTING = np.array(
    [5.5623e-09, 6.1259e-04, 5.3183e-02, 1.1884e-08, 490.34, -5941.1]
    + [1.7544e-01, -6.7920e-02, 1.3948e-02, 1.7180e-02, 1.3903e-01, 1.3438e-01, 1.5414e00]
)


def test_the_filters_model_retracts_smoothly_where_a_narrow_bypass_chatters(monkeypatch):
    """Over each 10 ms interval of a retraction, the transition's derivative stays below 1e7 in the scaled state
    (measured: 2e5 at most, 1e4 elsewhere on the pulse) with the bypass opening over `SWITCH_WIDTH`; over a band of
    10 Pa the model chatters there and the derivative overflows (measured: up to 1e34), the extended filter's
    covariance with it."""
    from growjax.track import model as tm

    inputs = gj.Inputs(
        catheter_length=gj.Sampled(np.array([0.0, 100.0]), np.array([0.004, 0.404])),
        pressure_demand=gj.published_pulse(),
    )
    starts = np.arange(9.30, 9.351, 0.005)  # the off phase ends at 9.36 s

    def largest_derivative():
        model = tk.state_space(gj.reference("forward"), sensors=ts.sensor_set("pressure,syringe"), estimate=("Y",))
        n = model.model_size
        x = jnp.asarray(np.concatenate([RETRACTING[:n] / np.asarray(model.scales()), RETRACTING[n:]]))
        breaks = model.breaks(inputs, 9.0, 9.4)
        step = jax.jit(lambda ta: model.linearised_advance(x, inputs, ta, ta + 0.01, breaks))
        out = [step(jnp.asarray(ta)) for ta in starts]
        assert all(int(status) == 0 for _, _, status in out)
        return max(float(jnp.max(jnp.abs(jac))) for _, jac, _ in out)

    assert largest_derivative() < 1e7
    monkeypatch.setattr(tm, "SWITCH_WIDTH", 10.0)
    assert largest_derivative() > 1e12
