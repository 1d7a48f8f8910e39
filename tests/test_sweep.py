"""Batched sweeps: design, equality with single runs, chunking, sharding, failures, Sobol, CLI."""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import growjax as gj
from growjax import sweep as sw
from growjax.data import experiment as ex

CFG = gj.Config(t1=2.0)
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def setup(synthetic_experiment):
    exp = synthetic_experiment
    base = gj.reference()
    return base, ex.to_inputs(exp, "forward", base), (exp.time, exp["robot_length_m"])


def test_latin_hypercube_is_reproducible_stratified_and_in_the_box():
    dims = sw.paper_box() + (sw.Dimension("fluid.air_fraction", 1e-4, 1e-2, log=True),)
    a, b = sw.latin_hypercube(dims, 50, seed=3), sw.latin_hypercube(dims, 50, seed=3)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, sw.latin_hypercube(dims, 50, seed=4))
    for i, d in enumerate(dims):
        assert np.all((a[:, i] >= d.low) & (a[:, i] <= d.high))
        u = (np.log(a[:, i] / d.low) / np.log(d.high / d.low)) if d.log else (a[:, i] - d.low) / (d.high - d.low)
        assert sorted(np.floor(u * 50).astype(int)) == list(range(50))  # one point per stratum


def test_dimension_parsing_names_the_problem():
    base = gj.reference()
    d = sw.parse_dimension("Y=5000:15000", base)
    assert (d.name, d.low, d.high, d.log) == ("robot.yield_pressure", 5000.0, 15000.0, False)
    assert sw.parse_dimension("air_fraction=1e-4:1e-2:log", base).log
    for bad, msg in [
        ("Y", "NAME=LOW:HIGH"),
        ("Y=1:x", "not numbers"),
        ("Y=5:1", "LOW < HIGH"),
        ("nope=1:2", "unknown parameter"),
        ("Y=0:1:log", "LOW > 0"),
    ]:
        with pytest.raises(ValueError, match=msg):
            sw.parse_dimension(bad, base)


def test_sweep_equals_one_at_a_time_and_chunking_changes_nothing(setup):
    base, inputs, measured = setup
    values = sw.latin_hypercube(sw.paper_box(), 5, seed=1)
    names = [d.name for d in sw.paper_box()]
    whole = sw.evaluate(values, names, base, inputs, CFG, measured=measured)
    seen = []
    chunked = sw.evaluate(
        values, names, base, inputs, CFG, measured=measured, chunk_size=2, on_chunk=lambda *a: seen.append(a)
    )
    assert seen == [(1, 3), (2, 3), (3, 3)]  # 5 rows in chunks of 2: the hook after each
    # Equal within the solver's own tolerance: XLA vectorises a batch of 1, 2 and 5 differently, and
    # rounding-level differences can move an adaptive step. The shift depends on the CPU's code generation
    # (1e-6 relative on one machine, 2.4e-5 on another for member 0 against its single run); the error
    # control bounds it by rtol (1e-4). A member given another's parameters would differ by far more (the
    # members' RMSEs differ by factors).
    tol = 2 * CFG.tolerances[0]
    np.testing.assert_allclose(whole.rmse, chunked.rmse, rtol=tol)
    np.testing.assert_allclose(whole.final_length, chunked.final_length, rtol=tol)
    single = jax.jit(lambda p, ts: gj.simulate(p, inputs, CFG, ts=ts))
    times, length = (np.asarray(a) for a in measured)
    inside = (times >= CFG.t0) & (times <= CFG.t1)
    ts = np.append(times[inside], CFG.t1) if times[inside][-1] < CFG.t1 else times[inside]
    for i in (0, 3):
        p = gj.replace(base, **dict(zip(names, values[i])))
        model = np.asarray(single(p, ts).length)
        at_samples = model[: inside.sum()]  # the sweep scores the model at the samples
        rmse = float(np.sqrt(np.mean((at_samples - length[inside]) ** 2)))
        assert whole.rmse[i] == pytest.approx(rmse, rel=tol)
        assert whole.final_length[i] == pytest.approx(float(model[-1]), rel=tol)
    assert np.all(whole.status == gj.OK)
    # Lower Y grows the robot further over the same pulses.
    order = np.argsort(values[:, 1])
    assert np.all(np.diff(whole.final_length[order]) < 0)


@pytest.mark.slow  # the paper sweep below runs the shared path in the default suite, judged by its result
def test_large_batches_compute_the_fields_shared_values_once_with_the_same_result(setup):
    """From ``SHARED_BATCH_MIN`` members per device the field passes its shared values through a dot
    (:func:`growjax.simulation.fast._computed_once`); the results equal those of small batches, which do not.

    The shared values differ from the recomputed ones by rounding (XLA's kernels differ), which can move an
    adaptive step: the runs then differ at the solver's tolerance (0.7 µm of length at the default rtol 1e-4,
    5e-9 m at 1e-6, measured). At rtol 1e-6 a real difference would show far above that.
    """
    from growjax.simulation import fast as fm

    base, inputs, measured = setup
    cfg = CFG.replace(rtol=1e-6)
    n = fm.SHARED_BATCH_MIN * len(jax.devices())
    values = sw.latin_hypercube(sw.paper_box(), n, seed=2)
    names = [d.name for d in sw.paper_box()]
    large = sw.evaluate(values, names, base, inputs, cfg, measured=measured, chunk_size=n)
    small = sw.evaluate(values, names, base, inputs, cfg, measured=measured, chunk_size=2)
    assert np.all(large.status == gj.OK) and np.all(small.status == gj.OK)
    np.testing.assert_allclose(large.rmse, small.rmse, rtol=0, atol=1e-7)
    np.testing.assert_allclose(large.final_length, small.final_length, rtol=0, atol=1e-7)


def test_failed_members_are_flagged_and_do_not_touch_the_others(setup):
    base, inputs, measured = setup
    names = ["Y", "t"]
    values = np.array([[8000.0, 3.5e-5], [np.nan, 3.5e-5], [-5.0, 3.5e-5], [8000.0, 1e-5], [9000.0, 3.5e-5]])
    res = sw.evaluate(values, names, base, inputs, CFG, measured=measured)
    assert res.reasons == ["ok", "invalid_parameter", "invalid_parameter", "pressure_limit", "ok"]
    assert np.all(np.isnan(res.rmse[1:4]))
    # The same two members in a batch without failures (same shape: the same compiled program).
    clean = sw.evaluate(values[[0, 4, 4, 4, 4]], names, base, inputs, CFG, measured=measured)
    np.testing.assert_allclose(res.rmse[[0, 4]], clean.rmse[:2], rtol=1e-5)
    assert clean.lower_s == 0.0 and res.lower_s <= res.compile_s  # the second call reuses the compiled program
    assert res.best_index in (0, 4)
    assert res.best()["rmse_length_m"] == pytest.approx(min(clean.rmse))


def test_sobol_indices_find_that_yield_pressure_dominates(setup):
    base, inputs, measured = setup
    out = sw.sobol_indices(sw.paper_box(), base, inputs, CFG, n_base=32, seed=0, measured=measured, n_bootstrap=200)
    s = out["indices"]["final_length_m"]
    y = out["names"].index("robot.yield_pressure")
    assert out["n_runs"] == 32 * 5
    assert s["ST"][y] > 0.9
    for i in range(3):
        if i != y:
            assert s["ST"][i] < 1e-6


def test_sweep_command_writes_table_figures_and_summary(tmp_path, capsys):
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "growjax.cli",
        "sweep",
        str(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv"),
        "--sets",
        "16",
        "--t-end",
        "2",
        "--seed",
        "5",
        "--chunk-size",
        "4",
        "--out",
        str(out),
        "--json",
        str(out / "s.json"),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    # progress on a pipe: plain lines, one per chunk here (4 chunks: every 25 %)
    assert "\r" not in proc.stderr and "sweep: 4/4 chunks (100 %)" in proc.stderr and len(proc.stderr) < 1000
    summary = json.loads((out / "s.json").read_text())
    assert summary["n_failed"] == 0 and summary["best"]["rmse_length_m"] > 0
    assert set(summary["best"]["parameters"]) == {
        "robot.growth_exponent",
        "robot.yield_pressure",
        "robot.extensibility",
    }
    assert summary["wall_s"] > 0 and 0 < summary["trace_lower_s"] < summary["compile_s"]  # a fresh process traces
    rows = (out / "sweep.csv").read_text().splitlines()
    assert len(rows) == 17 and rows[0].endswith("rmse_length_m,final_length_m,status")
    assert (
        out / "sweep.png"
    ).stat().st_size > 10_000  # (--sobol: test_sobol_indices_find_that_yield_pressure_dominates)
    from growjax import cli

    assert cli.main(["sweep", "--range", "Y=9:1"]) == 2 and "LOW < HIGH" in capsys.readouterr().err
    assert summary["store"] == str(out / "sweep.zarr") and sw.load(out / "sweep.zarr").reasons == summary_reasons(rows)

    # SIGINT while it compiles (tracing and lowering alone take a second; the signal follows the line by
    # milliseconds): a clean stop with the store kept and a line saying how to resume; --resume completes it to
    # the same table, bit for bit.
    stopped = tmp_path / "stopped"
    argv = [a if a != str(out) else str(stopped) for a in cmd[:-2]]
    run = subprocess.Popen(argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    for line in run.stderr:
        if "compiling" in line:
            break
    run.send_signal(signal.SIGINT)
    err = run.stderr.read()
    assert run.wait(timeout=600) == 130, err[-2000:]
    assert f"0 of 4 chunks kept in {stopped / 'sweep.zarr'}; complete it with: growjax sweep --resume {stopped}" in err
    assert "SIGINT received: stopping after the chunk in flight" in err
    assert not (stopped / "sweep.csv").exists()
    resumed = subprocess.run(
        [*cmd[:4], "--resume", str(stopped), "--quiet"], capture_output=True, text=True, timeout=600, check=False
    )
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert resumed.stderr == ""  # --quiet
    assert (stopped / "sweep.csv").read_bytes() == (out / "sweep.csv").read_bytes()


def summary_reasons(rows):
    return [r.rsplit(",", 1)[1] for r in rows[1:]]


def test_stored_sweep_stopped_and_resumed_equals_an_uninterrupted_one(setup, tmp_path):
    base, inputs, measured = setup
    whole = sw.lhs_sweep(6, base, inputs, CFG, seed=7, measured=measured, chunk_size=2)
    store = tmp_path / "store"
    with pytest.raises(sw.SweepInterrupted, match="2 of 3 chunks") as stop:
        sw.lhs_sweep(6, base, inputs, CFG, seed=7, measured=measured, chunk_size=2, store=store, max_chunks=2)
    assert (stop.value.done, stop.value.total, stop.value.signal) == (2, 3, None)
    part = sw.load(store)
    assert part.reasons == ["ok"] * 4 + ["not_run"] * 2
    np.testing.assert_array_equal(part.rmse[:4], whole.rmse[:4])
    assert np.all(np.isnan(part.rmse[4:]))
    resumed = sw.resume(store, base, inputs, measured)
    for field in ("values", "rmse", "final_length", "status"):  # bit for bit
        np.testing.assert_array_equal(getattr(resumed, field), getattr(whole, field), strict=True)
    assert resumed.names == whole.names
    again = sw.resume(store, base, inputs, measured)  # a finished store: read, nothing run
    np.testing.assert_array_equal(again.rmse, whole.rmse)
    with pytest.raises(ValueError, match="needs a store|give a store"):
        sw.lhs_sweep(6, base, inputs, CFG, measured=measured, max_chunks=1)


def test_a_signal_stops_a_stored_sweep_after_the_chunk_in_flight(setup, tmp_path):
    """SIGTERM raised as the first chunk is written (the ``on_chunk`` hook): that chunk is kept, the sweep stops
    before the next, and the hook has seen the one chunk done of three."""
    base, inputs, measured = setup
    seen = []

    def signalled(done, total):
        seen.append((done, total))
        if done == 1:
            os.kill(os.getpid(), signal.SIGTERM)

    with pytest.raises(sw.SweepInterrupted, match="1 of 3 chunks") as stop:
        sw.lhs_sweep(
            6, base, inputs, CFG, seed=7, measured=measured, chunk_size=2, store=tmp_path / "s", on_chunk=signalled
        )
    assert stop.value.signal == signal.SIGTERM
    assert seen == [(1, 3)]
    assert sw.load(tmp_path / "s").reasons == ["ok"] * 2 + ["not_run"] * 4
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handlers are put back


def test_a_second_signal_stops_at_once_but_not_inside_a_write():
    from growjax.sweep.stopping import Stopper

    with Stopper(announce=False) as stop:
        os.kill(os.getpid(), signal.SIGINT)
        assert stop.signal == signal.SIGINT  # the first only asks
        with pytest.raises(KeyboardInterrupt):
            with stop.writing():
                os.kill(os.getpid(), signal.SIGTERM)
                written = True  # the write goes on to its end
        assert written
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)


def _snapshot(folder: Path) -> dict:
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_resume_refuses_a_missing_corrupt_or_other_store_and_writes_nothing(setup, tmp_path):
    base, inputs, measured = setup
    store = tmp_path / "store"
    with pytest.raises(sw.SweepInterrupted):
        sw.lhs_sweep(4, base, inputs, CFG, seed=1, measured=measured, chunk_size=2, store=store, max_chunks=1)
    before = _snapshot(store)
    with pytest.raises(sw.StoreError, match="no such folder"):
        sw.resume(tmp_path / "absent", base, inputs, measured)
    with pytest.raises(sw.StoreError, match="already exists"):
        sw.lhs_sweep(4, base, inputs, CFG, seed=1, measured=measured, store=store)
    times, length = measured
    with pytest.raises(sw.StoreError, match="other measured data"):
        sw.resume(store, base, inputs, (times, length * 1.01))
    with pytest.raises(sw.StoreError, match="other base parameters"):
        sw.resume(store, gj.replace(base, Y=9100.0), inputs, measured)
    assert _snapshot(store) == before
    broken = tmp_path / "broken"
    shutil.copytree(store, broken)
    (broken / "status" / "c" / "0").write_bytes(b"not a chunk")
    with pytest.raises(sw.StoreError, match="corrupt sweep store"):
        sw.resume(broken, base, inputs, measured)
    (broken / "zarr.json").write_text("{")
    with pytest.raises(sw.StoreError, match="not a readable sweep store"):
        sw.resume(broken, base, inputs, measured)
    assert sw.resume(store, base, inputs, measured).reasons == ["ok"] * 4


def test_sweep_resume_errors_are_one_line_with_exit_2_and_change_nothing(tmp_path, capsys):
    from growjax import cli

    data = str(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv")
    folder = tmp_path / "run"
    argv = ["sweep", data, "--sets", "4", "--t-end", "2", "--seed", "5", "--chunk-size", "2", "--quiet"]
    assert cli.main([*argv, "--out", str(folder), "--max-chunks", "1"]) == 3
    assert f"growjax sweep --resume {folder}" in capsys.readouterr().err
    before = _snapshot(folder)
    broken = tmp_path / "broken"
    shutil.copytree(folder, broken)
    (broken / "sweep.zarr" / "zarr.json").write_text("{")
    cases = [
        (["--resume", str(tmp_path / "absent")], "no such folder"),
        (["--resume", str(folder), "--seed", "0"], "holds another sweep: --seed 0 here, 5 there"),
        (["--resume", str(folder), "--range", "Y=5000:9000"], "holds another sweep: --range"),
        (["--resume", str(broken)], "not a readable sweep store"),
        (["--resume", str(folder), "--out", str(tmp_path / "elsewhere")], "writes its results there"),
        ([*argv[1:], "--out", str(folder)], "holds an unfinished sweep"),
    ]
    for extra, message in cases:
        assert cli.main(["sweep", *extra]) == 2, extra
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    assert _snapshot(folder) == before


@pytest.mark.parametrize("n_sets", [48, pytest.param(500, marks=pytest.mark.slow)])
def test_paper_sweep_finds_the_published_yield_pressure_and_rmse(shared_experiment, n_sets):
    exp = shared_experiment
    base = gj.reference()
    inputs = ex.to_inputs(exp, "forward", base)
    res = sw.lhs_sweep(n_sets, base, inputs, gj.Config(), seed=0, measured=(exp.time, exp["robot_length_m"]))
    best = res.best()
    assert res.failed.sum() == 0
    assert 7.0e3 < best["parameters"]["robot.yield_pressure"] < 9.0e3  # paper: ≈ 7.9 kPa
    assert best["rmse_length_m"] < 1.75e-3  # paper: 1.7 mm
    # RMSE is a function of Y alone: sets with Y within 100 Pa of the best agree to 0.1 mm.
    near = np.abs(res.values[:, 1] - best["parameters"]["robot.yield_pressure"]) < 100.0
    assert np.ptp(res.rmse[near]) < 1e-4


@pytest.mark.slow  # two processes compiling on two cores: ~25 s
def test_sweep_command_as_two_processes_gives_the_single_process_result(tmp_path):
    """``--coordinator`` on 127.0.0.1: two processes of one device each split every chunk; process 0 writes the
    same table, bit for bit, as one process with two devices (the same rows per device)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    argv = [
        sys.executable,
        "-m",
        "growjax.cli",
        "sweep",
        "--sets",
        "8",
        "--chunk-size",
        "4",
        "--t-end",
        "1",
        "--seed",
        "2",
        "--quiet",
    ]
    env = {**os.environ, "GROWJAX_CPU_DEVICES": "1"}
    procs = [
        subprocess.Popen(
            [
                *argv,
                "--out",
                str(tmp_path / "two"),
                "--coordinator",
                f"127.0.0.1:{port}",
                "--num-processes",
                "2",
                "--process-id",
                str(i),
                "--json",
                str(tmp_path / f"{i}.json"),
            ],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in (0, 1)
    ]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    assert "wrote" in outs[0][0] and "sweep" not in outs[1][0]  # process 0 reports (Gloo prints its own lines)
    assert json.loads((tmp_path / "0.json").read_text())["n_processes"] == 2 and not (tmp_path / "1.json").exists()
    one = subprocess.run(
        [*argv, "--out", str(tmp_path / "one")],
        env={**env, "GROWJAX_CPU_DEVICES": "2"},
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert one.returncode == 0, one.stderr[-2000:]
    assert (tmp_path / "two" / "sweep.csv").read_bytes() == (tmp_path / "one" / "sweep.csv").read_bytes()
