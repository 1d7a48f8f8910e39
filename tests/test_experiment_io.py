"""Experiment files: clear errors for bad input, MATLAB decoding, and the stepper controller quirk."""

import numpy as np
import pytest

import growjax as gj
from growjax.data import experiment as ex
from growjax.model.motor import step_schedule

GOOD = "time_s,robot_length_m,catheter_length_m\n0.0,0.010,0.004\n0.1,0.011,0.005\n0.2,0.012,0.006\n"


def _write(tmp_path, text):
    path = tmp_path / "exp.csv"
    path.write_text(text)
    return path


def test_good_file_reads(tmp_path):
    exp = ex.read(_write(tmp_path, GOOD))
    np.testing.assert_allclose(exp["robot_length_m"], [0.010, 0.011, 0.012])


@pytest.mark.parametrize(
    "text, message",
    [
        (GOOD.replace("0.011,", "nan,"), "NaN"),
        (GOOD.replace("0.1,", "0.3,"), "not sorted"),
        (GOOD.replace("0.2,", "0.1,"), "duplicate"),
        (GOOD.replace("0.2,", "0.10000000000000009,"), "duplicate times .two samples within 1e-09 s"),
        (GOOD.replace("0.010,", "10.0,").replace("0.011,", "11.0,").replace("0.012,", "12.0,"), "millimetres"),
        (GOOD.replace("0.011,", "-0.011,"), "negative"),
        (GOOD.replace("time_s", "time"), "no time_s"),
        ("time_s,foo\n0,1\n1,2\n", "none of the columns"),
        (GOOD.replace("robot_length_m", "robot_length_mm"), "millimetres"),
        ("time_s,robot_length_m\n0.0,0.010\n0.1,0.011\n", r"exp\.csv has no catheter_length_m column.*--no-catheter"),
    ],
)
def test_bad_files_get_clear_errors(tmp_path, text, message):
    with pytest.raises(ex.ExperimentError, match=message):
        ex.read(_write(tmp_path, text))


def test_a_binary_file_is_named_and_not_decoded(tmp_path):
    path = tmp_path / "run.csv"
    path.write_bytes(b"\x80\x81\x82 not utf-8")
    with pytest.raises(ex.ExperimentError, match=r"run\.csv is not a text CSV") as err:
        ex.read(path)
    assert "codec" not in str(err.value)
    mat = tmp_path / "kings_ts.mat"
    mat.write_bytes(b"MATLAB 5.0 MAT-file\x00\xff\xfe")
    with pytest.raises(ex.ExperimentError, match="give the folder holding kings_ts.mat and lin_c_ts.mat"):
        ex.read(mat)


def test_a_spreadsheet_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbf" + GOOD.encode())
    np.testing.assert_allclose(ex.read(path)["catheter_length_m"], [0.004, 0.005, 0.006])


def test_without_a_catheter_only_when_said_so(tmp_path):
    """No catheter_length_m: an error unless catheter=False, which takes the catheter as zero and refuses a column."""
    exp = ex.read(_write(tmp_path, "time_s,robot_length_m\n0.0,0.010\n0.1,0.011\n"), catheter=False)
    assert "catheter_length_m" not in exp
    inputs = ex.to_inputs(exp, "forward", gj.reference())
    assert float(inputs.catheter_length(0.05)) == 0.0
    with pytest.raises(ex.ExperimentError, match="gives the catheter length.*drop one or the other"):
        ex.read(_write(tmp_path, GOOD), catheter=False)


def test_a_matlab_folder_without_the_catheter_file(tmp_path, shared_experiment):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "kings_ts.mat").write_bytes((ex.shared_experiment_dir() / "kings_ts.mat").read_bytes())
    with pytest.raises(ex.ExperimentError, match=r"has no lin_c_ts\.mat.*--no-catheter"):
        ex.read(folder)
    exp = ex.read(folder, catheter=False)
    assert set(exp.series) == {"robot_length_m"}
    np.testing.assert_allclose(exp["robot_length_m"], shared_experiment["robot_length_m"], rtol=1e-9)
    with pytest.raises(ex.ExperimentError, match=r"lin_c_ts\.mat.*drop one"):
        ex.read(ex.shared_experiment_dir(), catheter=False)


def test_inverse_drive_needs_a_length_column(tmp_path):
    exp = ex.read(_write(tmp_path, "time_s,catheter_length_m\n0,0.001\n1,0.002\n"))
    with pytest.raises(ex.ExperimentError, match="desired_length_m"):
        ex.to_inputs(exp, "inverse", gj.reference("inverse"))


def test_mat_files_decode_to_the_csv(shared_experiment):
    folder = ex.shared_experiment_dir()
    mat = ex.read(folder)
    np.testing.assert_allclose(mat.time, shared_experiment.time, rtol=1e-12)
    np.testing.assert_allclose(mat["robot_length_m"], shared_experiment["robot_length_m"], rtol=1e-9)
    np.testing.assert_allclose(mat["catheter_length_m"], shared_experiment["catheter_length_m"], rtol=1e-9)


def test_sampled_signal_extrapolates_linearly():
    s = gj.Sampled(np.array([1.0, 2.0, 3.0]), np.array([10.0, 20.0, 40.0]))
    assert float(s(0.5)) == pytest.approx(5.0)
    assert float(s(2.5)) == pytest.approx(30.0)
    assert float(s(4.0)) == pytest.approx(60.0)


def test_shipped_controller_stalls_at_high_rate_and_moves_at_3hz(shared_experiment):
    params = gj.reference("inverse")
    demand = ex.demand_steps(params, shared_experiment["robot_length_m"])
    assert demand.min() == pytest.approx(2.89, abs=0.01) and demand.max() == pytest.approx(21.47, abs=0.01)
    fast_t, _ = step_schedule(demand, shared_experiment.time, 100.0, 0.001, 10.0)
    assert len(fast_t) == 3 and fast_t.max() < 0.05  # only the initial transient
    _, k3 = step_schedule(demand, shared_experiment.time, 3.0, 0.001, 10.0)
    final_demand = np.interp(10.0, shared_experiment.time, demand)
    assert abs(k3[-1] - final_demand) < 1.5
