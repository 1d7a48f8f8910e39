"""Experiment sets: the manifest, the scopes of free parameters, and the batched joint fit."""

import json
from importlib.resources import files
from pathlib import Path

import jax
import numpy as np
import pytest

import growjax as gj
from growjax import calibration as cal
from growjax import cli
from growjax.calibration import batch as cb
from growjax.cli import summary_lines
from growjax.data import experiment as ex
from growjax.data import sets as xs
from growjax.data.experiment import ExperimentError

REPO = Path(__file__).resolve().parents[1]
SET = Path(str(files("growjax.data") / "datasets" / "set"))
Y = "robot.yield_pressure"


def _write(tmp_path, text, csvs=("a.csv",)):
    t = np.arange(1, 101) * 0.01
    for name in csvs:
        rows = "\n".join(f"{x:.2f},{0.01 + 0.002 * x:.6f},{0.004:.6f}" for x in t)
        (tmp_path / name).write_text("time_s,robot_length_m,catheter_length_m\n" + rows + "\n")
    path = tmp_path / "set.toml"
    path.write_text(text)
    return path


def test_the_shipped_manifest_reads_as_one_robot_on_one_rig():
    exps = xs.read([SET / "set.toml"])
    assert len(exps) == 3 and exps.robots == ("membrane-1",) and exps.rigs == ("bench",)
    assert [r.sensors for r in exps] == [("length", "pressure"), ("length",), ("length",)]
    assert exps.group_of("robot") == ["membrane-1"] * 3 and exps.group_of("experiment") == [r.name for r in exps]


@pytest.mark.parametrize(
    "text, message",
    [
        ('[[experiment]]\nfile = "missing.csv"\n', "file missing.csv not found"),
        ('[[experiment]]\nfile = "a.csv"\nwindow = [20.0, 30.0]\n', "holds no data"),
        ('[[experiment]]\nfile = "a.csv"\nrig = "other"\n[rig.bench]\nparameters = {}\n', "unknown rig 'other'"),
        ('[[experiment]]\nfile = "a.csv"\nrobot = "r9"\n[robot.r1]\n', "unknown robot 'r9'"),
        ('[[experiment]]\nfile = "a.csv"\nsensors = ["length", "pressure"]\n', "no pressure_Pa column"),
        ('[[experiment]]\nfile = "a.csv"\ncolour = "red"\n', "unknown key"),
        ('[[experiment]]\nfile = "a.csv"\nparameters = { Q = 1.0 }\n', "unknown parameter 'Q'"),
        ("experiment = 3\n", "no [[experiment]] entries"),
    ],
)
def test_a_bad_manifest_is_one_error_naming_the_experiment_and_the_problem(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(ExperimentError, match=message.replace("[", r"\[").replace("]", r"\]")):
        xs.ExperimentSet.from_manifest(path)


def test_the_command_line_gives_bad_sets_and_scopes_exit_2_with_one_line(tmp_path, capsys):
    path = _write(tmp_path, '[[experiment]]\nfile = "a.csv"\nwindow = [20.0, 30.0]\n')
    assert cli.main(["fit", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "experiment 'a.csv'" in err[0] and "holds no data" in err[0]
    good = _write(tmp_path, '[[experiment]]\nfile = "a.csv"\n[[experiment]]\nfile = "b.csv"\n', ("a.csv", "b.csv"))
    for free, message in (("Q@robot", "unknown parameter 'Q'"), ("Y@membrane", "unknown scope 'membrane'")):
        assert cli.main(["fit", str(good), "--free", free, "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err


def test_scopes_parse_and_default():
    base = gj.reference()
    assert xs.Scope.parse("Y@robot", base) == xs.Scope(Y, "robot")
    assert xs.Scope.parse("ext", base) == xs.Scope("robot.extensibility", "shared")
    with pytest.raises(ValueError, match="unknown scope"):
        xs.Scope.parse("Y@lab", base)


@pytest.fixture(scope="module")
def shipped_set():
    exps = xs.read([SET / "set.toml"])
    truth = json.loads((SET / "truth.json").read_text())
    return exps, truth, gj.Config(t1=4.0)


def test_a_set_of_one_is_the_experiment_given_as_arrays(shipped_set):
    """One experiment of the set, fitted as the set's run and as arrays with their inputs and parameters (the way a
    single experiment was given): one code path, the same estimate, interval and budget, the hyperparameters'
    spread included."""
    exps, _, _ = shipped_set
    config = gj.Config(t1=2.0)
    run = exps.runs[1]
    likelihood = cal.Likelihood(tolerances={})
    as_run = cal.fit(xs.ExperimentSet((run,)), ["Y"], likelihood=likelihood, config=config, scout=0)
    inputs = ex.to_inputs(run.experiment, "forward", run.base(), config.t0, config.t1)
    arrays = xs.ExperimentSet.single(
        ex.Experiment(run.times, {"robot_length_m": run.length}), defaults=run.base(), inputs=inputs
    )
    as_arrays = cal.fit(arrays, ["Y"], likelihood=likelihood, config=config, scout=0)
    assert as_run.estimate[Y] == pytest.approx(as_arrays.estimate[Y], rel=1e-9)
    np.testing.assert_allclose(as_run.interval_90[Y], as_arrays.interval_90[Y], rtol=1e-9)
    assert as_run.budget[Y]["hyperparameters"] > 0.0
    assert as_run.budget[Y] == pytest.approx(as_arrays.budget[Y], rel=1e-9)
    assert as_run.discrepancy["amplitude_m"] == pytest.approx(as_run.runs[0]["discrepancy"]["amplitude_m"])


def test_the_shipped_set_fitted_jointly_covers(shipped_set):
    """Reference-made, one robot on one drawn rig, three demands: the joint interval covers the true Y, comes from
    one batched program (the experiment with the pressure sensor and the two without, padded alike), and the
    rig's errors, fitted in the model's own tangents, read the catheter friction (made 32 % low) as low and the
    screw friction (made 21 % high) as high."""
    exps, truth, config = shipped_set
    label = f"{Y}@membrane-1"
    together = cal.fit(exps, ["Y@robot"], config=config, scout=0)
    lo, hi = together.interval_90[label]
    assert lo <= truth["truth"]["Y"] <= hi and together.status == "converged"
    assert together.programs == 1 and len(together.runs) == 3
    assert all(r["rmse_length_m"] < 3e-4 for r in together.runs)
    read = together.rig_offset["bench"]
    assert read["robot.catheter_friction"] < -0.2 and read["pump.screw_viscous_friction"] > 0.1
    assert together.linearisations == 1 and together.rig_settled  # no secants to take again
    summary = together.summary()
    lines = summary_lines({**summary, "command": "fit", "experiments": [], "figure": "fit.png"})
    assert summary["rig_settled"] and not any("had not settled" in line for line in lines)
    unsettled = summary_lines(
        {
            **summary,
            "command": "fit",
            "experiments": [],
            "figure": "fit.png",
            "rig_settled": False,
            "linearisations": cal.RELINEARISE_STEPS,
            "rig_last_move": 0.12,
        }
    )
    assert any("had not settled after 8 linearisations" in line and "0.12 of a tolerance" in line for line in unsettled)


def test_runs_of_different_lengths_and_sensors_pad_to_one_program_and_keep_their_own_rows():
    """Three runs on one configuration, 80 and 50 samples, one with the pressure: padded to one tree of one shape
    (one compiled program), the padded samples repeat a run's last one, and each run's kept rows of the padded
    measurements are its own measurements, in order (its residuals, cut back, are the unpadded run's)."""
    cfg, base = gj.Config(t1=1.0), gj.reference("forward")
    inputs = gj.Inputs(catheter_length=gj.Constant(0.02), pressure_demand=gj.PulseTrain(amplitude=150e3))
    rng = np.random.default_rng(0)
    sizes, sensed = (80, 50, 50), (False, True, False)
    problems = []
    for m, p in zip(sizes, sensed):
        t = np.arange(1, m + 1) * 0.01
        problems.append(
            cal.make_problem(base, (Y,), inputs, cfg, t, rng.normal(size=m), rng.normal(size=m) if p else None)
        )
    padded, rows = cb.pad_samples(problems)
    shapes = {
        (jax.tree_util.tree_structure(pr), tuple(np.shape(x) for x in jax.tree_util.tree_leaves(pr))) for pr in padded
    }
    assert len(shapes) == 1
    for pr, pad, keep, m in zip(problems, padded, rows, sizes):
        own = np.concatenate([pr.length] + ([] if pr.pressure is None else [pr.pressure]))
        np.testing.assert_array_equal(np.concatenate([pad.length, pad.pressure])[keep], own)
        assert np.all(np.asarray(pad.times)[m:] == np.asarray(pr.times)[-1])
        np.testing.assert_array_equal(np.asarray(pad.times)[:m], pr.times)


@pytest.mark.slow
def test_the_shipped_sets_secants_settle_where_the_data_put_the_rig(shipped_set):
    """With the rig's secants instead of its tangents, linearised again at the rig it found, the joint fit settles
    (the slope there, not half a tolerance away) and agrees with the tangents' fit."""
    exps, truth, config = shipped_set
    label = f"{Y}@membrane-1"
    secants = cal.fit(exps, ["Y@robot"], config=config, scout=0, rig_tangents=False)
    tangents = cal.fit(exps, ["Y@robot"], config=config, scout=0)
    assert 1 < secants.linearisations < cal.RELINEARISE_STEPS
    assert secants.rig_settled and secants.rig_last_move <= cal.RELINEARISE_TOLERANCE
    assert abs(secants.estimate[label] - tangents.estimate[label]) < tangents.standard_error[label]


@pytest.mark.slow
def test_an_unshared_rig_claims_more_than_the_shipped_set_can_say(shipped_set):
    """Taking the rig's errors as independent per experiment narrows the joint interval: more than the runs on one
    rig can say (over 30 drawn sets it under-covers: ``benchmarks/sets.py``)."""
    exps, _, config = shipped_set
    label = f"{Y}@membrane-1"
    shared = np.diff(cal.fit(exps, ["Y@robot"], config=config, scout=0).interval_90[label])[0]
    independent = cal.fit(exps, ["Y@robot"], likelihood=cal.Likelihood(rig_errors="experiment"), config=config, scout=0)
    assert np.diff(independent.interval_90[label])[0] < shared


@pytest.mark.slow
def test_the_shipped_set_fitted_jointly_beats_each_experiment_alone(shipped_set):
    """The joint interval is narrower than the best single experiment's (over 30 drawn sets:
    ``benchmarks/sets.py``)."""
    exps, _, config = shipped_set
    label = f"{Y}@membrane-1"
    fit = lambda runs: cal.fit(xs.ExperimentSet(runs), ["Y@robot"], config=config, starts=1, scout=16)
    together = np.diff(fit(exps.runs).interval_90[label])[0]
    best_single = min(np.diff(fit((r,)).interval_90[label])[0] for r in exps.runs)
    assert together < best_single


_SPREAD = """
import jax
jax.config.update("jax_num_cpu_devices", 2)
jax.config.update("jax_enable_x64", True)
import numpy as np
import growjax as gj
from growjax import calibration as cal
from growjax.calibration import batch as cb

cfg = gj.Config(t1=1.0)
base = gj.reference("forward")
problems = []
for k, amplitude in enumerate((100e3, 125e3, 150e3, 175e3, 200e3)):
    inputs = gj.Inputs(catheter_length=gj.Sampled(np.array([0.0, 10.0]), np.full(2, 0.02)),
                       pressure_demand=gj.PulseTrain(amplitude=amplitude))
    times = np.arange(1, 101) * 0.01
    problems.append(cal.make_problem(base, ("robot.yield_pressure",), inputs, cfg, times, np.full(100, 0.01)))
stacked = cb.stack(cb.pad_breaks(problems))
z = jax.numpy.asarray([[0.0], [0.1], [-0.1], [0.05], [-0.05]])
calls = []
shared = cb.sharded
cb.sharded = lambda *a: calls.append(a[1].size) or shared(*a)  # the devices each call spreads over
spread, _ = cb.spread(cb.residuals_runs, z, stacked)
assert calls == [2], calls
alone, _ = cb.on_one_device(cb.residuals_runs, z, stacked)
print(len(jax.devices()), float(np.max(np.abs(np.asarray(spread) - np.asarray(alone)))),
      float(np.max(np.abs(np.asarray(alone)))))
"""


def test_runs_spread_over_two_devices_give_what_one_device_gives():
    """Five runs on a process with two CPU devices: the first device solves three, the second two and a padding
    copy; each run's residuals are those of the one-device program."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _SPREAD], capture_output=True, text=True, timeout=600, check=True)
    devices, gap, size = out.stdout.split()
    assert int(devices) == 2
    assert float(size) > 1.0 and float(gap) < 1e-6 * float(size)
