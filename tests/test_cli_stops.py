"""Commands that stop before their end: Ctrl-C and SIGTERM (exit 130 and 143, one line naming what was written),
a write that fails at the end (exit 1, one line, what was written kept), and the summaries of runs that failed,
which never report a figure from after the stop as if the run had gone on."""

import errno
import json
import os
import signal
import time
import types
from pathlib import Path

from growjax import cli
from growjax.cli import command, options


class _Echo:
    """A command (``growjax echo``) that writes ``partial.txt`` into ``--out`` and then does what ``then`` says."""

    def __init__(self, then):
        self.then = then

    def module(self):
        echo = types.ModuleType("echo")
        echo.NAME, echo.HELP, echo.PROCESS = "echo", "write a file, then stop", command.Process()

        def add_arguments(parser):
            parser.add_argument("--out", default="out/echo")
            options.json_option(parser)

        def run(args):
            (command.out_dir(args) / "partial.txt").write_text("kept\n")
            return self.then(args)

        echo.add_arguments, echo.run = add_arguments, run
        echo.summary_lines = lambda s: [f"echo: {s['value']}"]
        return echo


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def _terminate(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(30)  # the handler raises in this thread before the sleep ends
    raise AssertionError("SIGTERM did not stop the command")


def test_ctrl_c_during_a_fit_exits_130_in_one_line_before_writing_anything(monkeypatch, tmp_path, capsys):
    import growjax.calibration as cal

    monkeypatch.setattr(cal, "fit", _interrupt)
    assert cli.main(["fit", "--quiet", "--out", str(tmp_path / "out")]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["growjax fit: interrupted before writing anything"]
    assert not (tmp_path / "out").exists()


def test_ctrl_c_during_a_posterior_exits_130_and_sigterm_143(monkeypatch, tmp_path, capsys):
    from growjax import posterior as gpost

    monkeypatch.setattr(gpost, "sample", _interrupt)
    argv = ["posterior", "--quiet", "--out", str(tmp_path / "out"), "--json", str(tmp_path / "p.json")]
    assert cli.main(argv) == 130
    assert capsys.readouterr().err.strip().splitlines() == ["growjax posterior: interrupted before writing anything"]
    before = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(gpost, "sample", _terminate)
    assert cli.main(argv) == 143
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["growjax posterior: stopped by SIGTERM before writing anything"]
    assert signal.getsignal(signal.SIGTERM) is before  # the handler is the command's only while it runs
    assert not (tmp_path / "p.json").exists()


def test_an_interrupted_command_names_and_keeps_what_it_wrote(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(cli, "COMMANDS", (*cli.COMMANDS, _Echo(_interrupt).module()))
    out = tmp_path / "out"
    assert cli.main(["echo", "--out", str(out)]) == 130
    assert capsys.readouterr().err.strip() == f"growjax echo: interrupted; wrote {out / 'partial.txt'}"
    assert (out / "partial.txt").read_text() == "kept\n"


def test_a_write_that_fails_during_or_after_the_run_is_one_line_and_exit_1(monkeypatch, tmp_path, capsys):
    """Disk full while the command writes: exit 1, one line naming the file and the reason, what was written
    kept; at the JSON summary: the summary for people still printed."""

    def disk_full(args):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(Path(args.out) / "figure.png"))

    out = tmp_path / "out"
    monkeypatch.setattr(cli, "COMMANDS", (*cli.COMMANDS, _Echo(disk_full).module()))
    assert cli.main(["echo", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (
        f"growjax echo: failed: could not write {out / 'figure.png'} (No space left on device); "
        f"kept {out / 'partial.txt'}"
    )

    monkeypatch.setattr(cli, "COMMANDS", (*cli.COMMANDS[:-1], _Echo(lambda args: {"value": 7}).module()))
    summary = tmp_path / "s.json"
    real_write = Path.write_text

    def write_text(self, *args, **kwargs):
        if self == summary:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))
        return real_write(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", write_text)
    assert cli.main(["echo", "--out", str(out), "--json", str(summary)]) == 1
    captured = capsys.readouterr()
    assert captured.out.strip() == "echo: 7"
    assert captured.err.strip().splitlines() == [
        f"growjax echo: failed: the JSON summary: could not write {summary} (No space left on device); "
        f"kept {out / 'partial.txt'}"
    ]


# -- the summaries of runs that failed --------------------------------------------------------------------------


def _simulated(status: str, **fields) -> dict:
    return {
        "command": "simulate",
        "data": "run.csv",
        "drive": "forward",
        "fidelity": "fast",
        "t_end_s": 2.0,
        "parameters": {"recorded_beside_data": {}, "fixed": {}},
        "status": status,
        "pressure_limit_Pa": 373.3e3,
        "solver_steps": 40,
        "wall_s": 0.01,
        "first_call_s": 1.0,
        "trajectory_csv": "out/trajectory.csv",
        "figure": "out/trajectory.png",
        **fields,
    }


def test_a_run_stopped_at_the_membrane_limit_reports_its_stop_and_nothing_after():
    s = _simulated(
        "pressure_limit", stop_time_s=0.0026, final_time_s=0.0026, final_length_m=0.01001, peak_pressure_Pa=373.3e3
    )
    text = "\n".join(cli.summary_lines(s))
    assert "the sensed pressure reached the membrane limit 373.3 kPa at t = 0.003 s; the run stopped there" in text
    assert "at the stop: length 10.01 mm; peak pressure up to it 373.3 kPa; nothing simulated after it" in text
    assert "final length" not in text and "RMSE" not in text


def test_a_failed_solver_reports_its_last_sample_before_the_stop():
    s = _simulated("solver_failed", stop_time_s=1.2345, final_time_s=1.23, final_length_m=0.02, peak_pressure_Pa=150e3)
    text = "\n".join(cli.summary_lines(s))
    assert "status solver_failed: the solver stopped at t = 1.234 s" in text
    assert "at t = 1.230 s (the last sample before the stop): length 20.00 mm" in text
    assert "final length" not in text


def _fitted(status: str) -> dict:
    return {
        "command": "fit",
        "data": "run.csv",
        "drive": "forward",
        "t_end_s": 10.0,
        "t_start_s": 0.001,
        "status": status,
        "fixed_parameters": {},
        "parameters": {"Y": {"estimate": 9000.0, "interval_90": [8900.0, 9100.0], "budget_sd": {}}},
        "rmse_length_m": 2e-4,
        "wall_s": 3.0,
        "figure": "out/fit.png",
    }


def test_a_fit_that_did_not_converge_shows_no_interval():
    converged = "\n".join(cli.summary_lines(_fitted("converged")))
    assert "Y = 9.000 kPa (90 % 8.900 kPa – 9.100 kPa)" in converged and "not converged" not in converged
    stopped = "\n".join(cli.summary_lines(_fitted("max_steps")))
    assert "not converged: the values below are where the search stopped" in stopped
    assert "Y = 9.000 kPa (where the search stopped)" in stopped and "90 %" not in stopped


def test_chains_that_did_not_mix_are_said_not_to_give_the_posterior():
    s = {
        "command": "posterior",
        "data": "run.csv",
        "growth_law": "reference",
        "chains": 4,
        "warmup": 50,
        "samples": 50,
        "fixed_parameters": {},
        "parameters": {"Y": {"mean": 9000.0, "interval_90": [8000.0, 10000.0]}},
        "rhat_max": 1.6,
        "ess_bulk_min": 8.0,
        "divergences": 0,
        "coverage_90": 0.9,
        "wall_s": 10.0,
        "inference_data": "out/posterior.nc",
    }
    assert "did not mix (R-hat max 1.6 > 1.1): the intervals below are not the posterior's" in "\n".join(
        cli.summary_lines(s)
    )
    assert "did not mix" not in "\n".join(cli.summary_lines({**s, "rhat_max": 1.01}))


def test_a_population_stopped_at_its_joint_fit_reports_that_and_no_population(monkeypatch, tmp_path, capsys):
    """The joint fit does not converge: exit 1, the summary says no population was sampled (and is written)."""
    import growjax.calibration as cal

    class NotConverged:
        status = "max_steps"

        def summary(self):
            return {"status": self.status}

    monkeypatch.setattr(cal, "fit", lambda *a, **k: NotConverged())
    manifest = Path(__file__).parents[1] / "src/growjax/data/datasets/population/population.toml"
    out, summary = tmp_path / "out", tmp_path / "p.json"
    argv = ["posterior", str(manifest), "--hierarchical", "Y", "--quiet", "--out", str(out), "--json", str(summary)]
    assert cli.main(argv) == 1
    captured = capsys.readouterr()
    assert "the joint fit did not converge (max_steps); no population was sampled" in captured.out
    assert captured.err.strip().splitlines()[-1].startswith("growjax posterior: failed: the joint fit did not converge")
    assert json.loads(summary.read_text())["joint_fit"]["status"] == "max_steps"


def test_a_sweep_with_failed_members_takes_its_best_among_those_that_ran():
    s = {
        "command": "sweep",
        "data": "run.csv",
        "n": 10,
        "seed": 0,
        "parameters": {},
        "ranges": [{"name": "robot.yield_pressure", "low": 5e3, "high": 15e3, "log": False}],
        "n_failed": 3,
        "wall_s": 1.0,
        "compile_s": 5.0,
        "n_devices": 2,
        "device": "cpu",
        "best": {"parameters": {"robot.yield_pressure": 9000.0}, "rmse_length_m": 3e-4},
        "table_csv": "out/sweep.csv",
        "figure": "out/sweep.png",
    }
    text = "\n".join(cli.summary_lines(s))
    assert "3 failed" in text and "best of the 7 that ran to their end: robot.yield_pressure = 9.000 kPa" in text
    none = "\n".join(cli.summary_lines({**s, "n_failed": 10, "best": None}))
    assert "no set ran to its end: no best" in none


def test_a_control_evaluation_that_failed_reports_no_tracking_error():
    s = {
        "command": "control",
        "data": "run.csv",
        "drive": "forward",
        "method": "feedback",
        "evaluated_on": "reference",
        "fixed_parameters": {},
        "tracking_rmse_m": float("nan"),
        "peak_pressure_Pa": 120e3,
        "pressure_limit_Pa": 373.3e3,
        "max_demand_Pa": 336e3,
        "status": "solver_failed",
    }
    text = "\n".join(cli.summary_lines(s))
    assert "did not reach its end (solver_failed): no tracking RMSE; peak pressure up to its failure 120.0 kPa" in text
    assert "nan" not in text
    ok = "\n".join(cli.summary_lines({**s, "status": "ok", "tracking_rmse_m": 4e-4}))
    assert "tracking RMSE 0.40 mm; peak pressure 120.0 kPa" in ok


def test_a_control_evaluation_stopped_at_the_membrane_limit_reports_the_limit_as_its_peak():
    """The samples after the stop are NaN: the peak of those before it lies below the limit the run reached."""
    s = {
        "command": "control",
        "data": "run.csv",
        "drive": "forward",
        "method": "feedback",
        "evaluated_on": "reference",
        "fixed_parameters": {},
        "tracking_rmse_m": float("nan"),
        "peak_pressure_Pa": 7.8e3,
        "pressure_limit_Pa": 373.3e3,
        "max_demand_Pa": 336e3,
        "status": "pressure_limit",
    }
    text = "\n".join(cli.summary_lines(s))
    assert "reached the membrane limit: no tracking RMSE; peak pressure 373.3 kPa" in text
    assert "7.8 kPa" not in text and "nan" not in text


def _designed(known_fit_status) -> dict:
    return {
        "command": "design",
        "data": "run.csv",
        "drive": "forward",
        "parameters": ["robot.yield_pressure"],
        "criterion": "D",
        "duration_s": 10.0,
        "p_max_Pa": 150e3,
        "knot_spacing_s": 0.5,
        "fixed_parameters": {},
        "known_fit_status": known_fit_status,
        "table": [],
        "checks": {"design": {"peak_pressure_Pa": 140e3, "peak_length_m": 0.05, "admissible": True}},
        "limits": {"pressure_ceiling_Pa": 336e3, "length_ceiling_m": 0.1},
        "random": {"admissible": 60, "drawn": 64},
        "wall_s": {"total_s": 30.0},
        "design_csv": "out/design.csv",
        "figure": "out/design.png",
        "summary_json": "out/summary.json",
    }


def test_a_design_on_a_fit_that_did_not_converge_says_so():
    stopped = "\n".join(cli.summary_lines(_designed("max_steps")))
    assert "what is known comes from a fit that did not converge (max_steps)" in stopped
    for status in ("converged", None):
        assert "did not converge" not in "\n".join(cli.summary_lines(_designed(status)))
