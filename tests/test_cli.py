"""The README's first command, end to end: growjax simulate on shipped data."""

import json
import subprocess
import sys

import numpy as np
import pytest

import growjax as gj
from growjax.data import experiment as ex


def test_simulate_command_writes_an_experiment_csv_a_figure_and_json(tmp_path):
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "growjax.cli",
        "simulate",
        "--t-end",
        "3",
        "--out",
        str(out),
        "--json",
        str(tmp_path / "s.json"),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=600)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "s.json").read_text())
    for key in ("rmse_length_m", "final_length_m", "peak_pressure_Pa", "solver_steps", "status"):
        assert key in summary
    assert summary["status"] == "ok"
    # The shipped data were made with Y = 9 kPa, recorded beside them: the command uses it and says so.
    assert summary["parameters"]["recorded_beside_data"] == {"Y": 9000.0}
    assert summary["rmse_length_m"] < 4e-4  # noise σ = 0.2 mm
    assert "recorded beside the data: Y = 9.000 kPa" in done.stdout and "length RMSE" in done.stdout
    assert not done.stdout.lstrip().startswith("{")  # a summary for people; JSON only on request
    traj = ex.read(out / "trajectory.csv")  # a trajectory reads back as an experiment
    assert traj.time[-1] == pytest.approx(3.0)
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert np.all(np.diff(traj.time) > 0)


def test_a_failed_run_exits_nonzero_with_the_reason_and_still_writes_its_summary(tmp_path):
    data = tmp_path / "loud.csv"
    t = np.round(np.arange(1, 201) * 0.01, 10)
    ex.write_csv(data, t, {"catheter_length_m": np.full(t.size, 0.02), "pressure_demand_Pa": np.full(t.size, 600e3)})
    cmd = [
        sys.executable,
        "-m",
        "growjax.cli",
        "simulate",
        str(data),
        "--t-end",
        "2",
        "--out",
        str(tmp_path / "o"),
        "--json",
        "-",
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=600)
    assert done.returncode == 1, done.stderr
    assert "membrane limit" in done.stderr.splitlines()[-1]
    summary = json.loads(done.stdout)  # --json -: stdout is the JSON alone
    assert summary["status"] == "pressure_limit" and "failure" in summary


def test_version_lists_and_option_errors(capsys):
    from growjax import __version__, cli

    with pytest.raises(SystemExit) as stop:
        cli.main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out.strip() == f"growjax {__version__}"

    assert cli.main(["params", "--json", "-"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)["parameters"]}
    y = rows["robot.yield_pressure"]
    assert (
        y["symbol"] == "Y" and y["unit"] == "Pa" and y["range"] == [0.0, 1e6] and y["value"] == pytest.approx(7920.46)
    )
    assert cli.main(["params"]) == 0 and "robot.yield_pressure" in capsys.readouterr().out

    assert cli.main(["effects"]) == 0
    text = capsys.readouterr().out
    assert "fluid_leak.conductance" in text and "separated by" in text

    with pytest.raises(SystemExit) as stop:
        cli.main(["discover", "--candidates", "bogus_effect"])
    err = capsys.readouterr().err.strip()
    assert stop.value.code == 2 and len(err.splitlines()) == 1
    assert "bogus_effect" in err and "fluid_leak" in err and "actuation_lag" in err


def test_every_command_shares_the_options_and_shows_defaults():
    from growjax import cli

    parser = cli.build_parser()
    commands = parser._subparsers._group_actions[0].choices
    for name in ("simulate", "sweep", "fit", "posterior", "discover", "control", "design"):
        sub = commands[name]
        options = {o for a in sub._actions for o in a.option_strings}
        assert {"--drive", "--param", "--t-end", "--out", "--json", "--quiet", "--config"} <= options, name
        assert ("--seed" in options) == (name != "simulate"), name  # every command that draws
        assert ("--fidelity" in options) == (name not in ("control", "design")), name
        assert sub.parse_args([]).out.replace("\\", "/") == f"out/{name}"
        helptext = sub.format_help()
        assert all(a.help for a in sub._actions), name
        assert "(default: out/" in " ".join(helptext.split()), name
    assert "--range" in {o for a in commands["sweep"]._actions for o in a.option_strings}
    for name in ("simulate", "sweep", "fit", "posterior", "discover", "control", "design"):  # progress, or none
        assert commands[name].parse_args(["--quiet"]).quiet and not commands[name].parse_args([]).quiet


def test_simulate_command_reports_bad_input(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,robot_length_m\n0,10\n1,11\n")
    done = subprocess.run(
        [sys.executable, "-m", "growjax.cli", "simulate", str(bad), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )
    assert done.returncode == 2 and "millimetres" in done.stderr


def test_a_command_is_one_module_listed_in_the_registry(monkeypatch, tmp_path, capsys):
    """A module with NAME, HELP, PROCESS, add_arguments, run and summary_lines, listed in COMMANDS, is a command:
    its options parsed (a bad value exit 2), its summary written as JSON and shown in lines (exit 0), its failure
    exit 1 with the reason and the summary still written."""
    import types

    from growjax import cli
    from growjax.cli import command, options

    echo = types.ModuleType("echo")
    echo.NAME, echo.HELP, echo.PROCESS = "echo", "say a pressure back in kPa", command.Process()

    def add_arguments(parser):
        options.add(parser, (options.option("--value", type=options.positive, default=1e3, help="a pressure, Pa"),))
        options.json_option(parser)

    def run(args):
        summary = {"command": "echo", "value_Pa": args.value}
        if args.value > 2e5:
            raise command.RunFailed("above 200 kPa", summary)
        return summary

    echo.add_arguments, echo.run = add_arguments, run
    echo.summary_lines = lambda s: [f"echo: {s['value_Pa'] / 1e3:g} kPa"]
    monkeypatch.setattr(cli, "COMMANDS", (*cli.COMMANDS, echo))

    assert cli.main(["echo", "--value", "2e3", "--json", str(tmp_path / "e.json")]) == 0
    assert capsys.readouterr().out.strip() == "echo: 2 kPa"
    assert json.loads((tmp_path / "e.json").read_text()) == {"command": "echo", "value_Pa": 2000.0}
    assert cli.main(["echo", "--value", "3e5", "--json", str(tmp_path / "f.json")]) == 1
    assert capsys.readouterr().err.strip() == "growjax echo: failed: above 200 kPa"
    assert json.loads((tmp_path / "f.json").read_text())["failure"] == "above 200 kPa"
    with pytest.raises(SystemExit) as stop:
        cli.main(["echo", "--value", "-1"])
    assert stop.value.code == 2 and "--value: must be a positive number" in capsys.readouterr().err
    assert "echo" in cli.build_parser().format_help()


@pytest.mark.parametrize(
    "argv, named",
    [
        (["posterior", "--chains", "0"], "--chains: must be at least 1, got 0"),
        (["posterior", "--samples", "-5"], "--samples: must be at least 1, got -5"),
        (["posterior", "--warmup", "-1"], "--warmup: must be at least 0, got -1"),
        (["sweep", "--sets", "0"], "--sets: must be at least 1"),
        (["sweep", "--sobol-points", "100"], "--sobol-points: must be a power of 2"),
        (["sweep", "--chunk-size", "0"], "--chunk-size: must be at least 1"),
        (["fit", "--starts", "0"], "--starts: must be at least 1"),
        (["discover", "--workers", "-2"], "--workers: must be at least 1"),
        (["control", "--tuning-draws", "0"], "--tuning-draws: must be at least 1"),
        (["control", "--iterations", "two"], "--iterations: 'two' is not an integer"),
        (["control", "--microsteps", "0"], "--microsteps: must be at least 1"),
        (["fit", "--seed", "-1"], "--seed: must be at least 0"),
        (["design", "--scout", "0"], "--scout: must be at least 1"),
        (["design", "--check-draws", "1"], "--check-draws: must be at least 2"),
        (["simulate", "--t-end", "0"], "--t-end: must be a positive number"),
        (["fit", "--rtol=-1e-6"], "--rtol: must be a positive number"),
    ],
)
def test_counts_and_spans_are_checked_by_the_parser(argv, named, capsys):
    from growjax import cli

    with pytest.raises(SystemExit) as stop:
        cli.main(argv)
    err = capsys.readouterr().err.strip()
    assert stop.value.code == 2 and len(err.splitlines()) == 1 and named in err, err


def _rows(path, header, times):
    cols = header.split(",")
    values = {"time_s": None, "robot_length_m": 0.010, "catheter_length_m": 0.004, "pressure_demand_Pa": 150e3}
    path.write_text(
        header
        + "\n"
        + "".join(",".join(str(t) if c == "time_s" else str(values[c]) for c in cols) + "\n" for t in times)
    )
    return path


def test_a_failure_of_the_computation_is_not_reported_as_bad_input(monkeypatch, tmp_path):
    """A singular matrix is a ValueError to NumPy, but the input was fine: it is raised, not exit 2."""
    from growjax import cli

    def singular(args):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(cli.simulate, "run", singular)
    with pytest.raises(np.linalg.LinAlgError, match="Singular matrix"):
        cli.main(["simulate", "--out", str(tmp_path / "out")])
    monkeypatch.setattr(cli.simulate, "run", lambda args: (_ for _ in ()).throw(ValueError("bad --x")))
    assert cli.main(["simulate", "--out", str(tmp_path / "out")]) == 2


def test_bad_experiments_exit_2_with_one_line_naming_the_file(tmp_path, capsys):
    from growjax import cli

    binary = tmp_path / "binary.csv"
    binary.write_bytes(bytes(range(128, 256)))
    no_catheter = _rows(tmp_path / "no_catheter.csv", "time_s,robot_length_m", [0.01, 0.1, 0.2])
    late = _rows(tmp_path / "late.csv", "time_s,robot_length_m,catheter_length_m", [20.0, 21.0, 22.0])
    both = _rows(tmp_path / "both.csv", "time_s,robot_length_m,catheter_length_m", [0.01, 0.1, 0.2])
    cases = [
        (["simulate", str(binary)], "binary.csv is not a text CSV"),
        (["simulate", str(no_catheter)], "no_catheter.csv has no catheter_length_m column"),
        (["fit", str(no_catheter)], "--no-catheter"),
        (["control", str(no_catheter)], "no_catheter.csv has no catheter_length_m column"),
        (["simulate", str(late)], "late.csv holds data over 20–22 s and the simulated window is 0.001–10 s"),
        (["simulate", str(both), "--no-catheter"], "both.csv gives the catheter length"),
    ]
    for argv, named in cases:
        assert cli.main([*argv, "--out", str(tmp_path / "out")]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and named in err, (argv, err)
        assert "codec" not in err and "Traceback" not in err


def test_a_window_longer_than_the_data_is_shrunk_to_them_with_a_note(tmp_path, capsys):
    from growjax import cli
    from growjax.cli import loader, options

    short = _rows(tmp_path / "short.csv", "time_s,robot_length_m,pressure_demand_Pa", [0.01, 0.1, 0.2])
    args = cli.build_parser().parse_args(["simulate", str(short), "--no-catheter"])
    exp = loader.load(args).experiment
    assert args.t_end == pytest.approx(0.2) and options.make_config(args).t1 == pytest.approx(0.2)
    assert "catheter_length_m" not in exp and exp.time.size == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "note" in err and "0.01–0.2 s" in err and "0.001–10 s" in err, err
    args = cli.build_parser().parse_args(["simulate", str(short), "--no-catheter", "--t-end", "0.15"])
    exp = loader.load(args).experiment  # a window inside the data: kept, silently
    assert args.t_end == 0.15 and exp.time.size == 2 and capsys.readouterr().err == ""


class _Designed(Exception):
    """Raised by a stand-in for the design once it has seen its arguments."""


def test_control_gives_the_design_the_fixed_parameters_and_tolerances(tmp_path, monkeypatch, capsys):
    from growjax import cli
    from growjax import control as gc

    seen = {}

    def design(*args, **kw):
        seen.update(kw)
        raise _Designed

    monkeypatch.setattr(gc, "design_controller", design)
    with pytest.raises(_Designed):
        cli.main(["control", "--param", "ext=2e-6", "--robust-rig", "--tolerance", "Kp=0.1", "--out", str(tmp_path)])
    assert float(gj.get(seen["base"], "ext")) == 2e-6
    assert float(gj.get(seen["base"], "Y")) == 9000.0  # recorded beside the shipped data
    assert seen["tolerances"]["Kp"] == 0.1 and seen["tolerances"]["tank.length"] == 0.05  # on the default budget
    with pytest.raises(_Designed):
        cli.main(["control", "--out", str(tmp_path)])
    assert seen["tolerances"] is None and float(gj.get(seen["base"], "ext")) == float(gj.get(gj.reference(), "ext"))
    assert (seen["evaluate_on"], seen["n_draws"]) == ("reference", 8)
    with pytest.raises(_Designed):  # the default budget, tuned on 3 draws, evaluated on the fast configuration
        cli.main(["control", "--robust-rig", "--tuning-draws", "3", "--evaluate-on", "fast", "--out", str(tmp_path)])
    from growjax.calibration import tolerance as tl

    assert seen["tolerances"] == tl.default_budget(gj.reference()) and seen["tolerances"]["tank.length"] == 0.05
    assert (seen["evaluate_on"], seen["n_draws"]) == ("fast", 3)
    for argv, named in (
        (["--tolerance", "Kp=0.1"], "add --robust-rig"),
        (["--robust-rig", "--tolerance", "none"], "no rig tolerance to draw"),
    ):
        assert cli.main(["control", *argv, "--out", str(tmp_path)]) == 2
        assert named in capsys.readouterr().err


def test_design_takes_the_growth_law_of_what_is_known(tmp_path, monkeypatch):
    """``growjax design --law lockhart``: what is known and the design are on Lockhart's law; a saved fit that left
    its rate and exponent undetermined gives them their box (uniform) prior."""
    from growjax import cli
    from growjax import design as gd

    seen = {}

    def design(knowledge, space, **kw):
        seen["knowledge"] = knowledge
        raise _Designed

    monkeypatch.setattr(gd, "design", design)
    saved = tmp_path / "fit.json"
    saved.write_text(
        json.dumps(
            {
                "parameters": {
                    "robot.yield_pressure": {"estimate": 9000.0, "standard_error": 200.0},
                    "robot.lockhart_rate": {"estimate": 9.0, "standard_error": None},
                    "robot.lockhart_exponent": {"estimate": 0.05, "standard_error": None},
                }
            }
        )
    )
    with pytest.raises(_Designed):
        cli.main(
            [
                "design",
                "--law",
                "lockhart",
                "--for",
                "Y,phi_L,n_L",
                "--fit-from",
                str(saved),
                "--out",
                str(tmp_path / "out"),
            ]
        )
    known = seen["knowledge"]
    assert known.base.robot.growth_law == "lockhart"
    assert known.names == ("robot.yield_pressure", "robot.lockhart_rate", "robot.lockhart_exponent")
    reference = gj.reference(growth_law="lockhart")
    for name in known.names[1:]:  # undetermined: at the box's centre, with its variance
        assert float(gj.get(known.base, name)) == pytest.approx(float(gj.get(reference, name)))
        assert known.covariance[known.names.index(name), known.names.index(name)] == pytest.approx(
            np.log(4.0) ** 2 / 12
        )


@pytest.mark.slow
def test_posterior_command_writes_inference_data_and_the_summary_keys(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "growjax.cli",
        "posterior",
        "--t-end",
        "0.8",
        "--chains",
        "2",
        "--warmup",
        "40",
        "--samples",
        "40",
        "--emulate",
        "--out",
        str(tmp_path),
        "--json",
        str(tmp_path / "p.json"),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=900)
    assert done.returncode == 0, done.stderr
    # stderr is a pipe: a line per phase, no bars (NumPyro's redraw with carriage returns)
    assert "\r" not in done.stderr and len(done.stderr.encode()) < 5000, done.stderr[-2000:]
    assert "posterior: building the emulator" in done.stderr and "posterior: NUTS done in" in done.stderr
    summary = json.loads((tmp_path / "p.json").read_text())
    for key in ("parameters", "rhat_max", "ess_bulk_min", "divergences", "wall_s", "coverage_90"):
        assert key in summary
    assert set(summary["parameters"]) == {"Y", "ext", "n", "sigma"}
    lo, hi = summary["parameters"]["Y"]["interval_90"]
    # The shipped data come from the reference configuration (Y = 9 kPa, σ = 0.2 mm); over 0.8 s the fast model's
    # interval sits ~1–3 % above the truth (open, see tests/test_calibration.py), so this checks the command only.
    assert 8500.0 < lo < hi < 10000.0
    assert (tmp_path / "posterior.nc").stat().st_size > 10_000


def test_fit_passes_the_rigs_treatment_to_the_fit(monkeypatch, tmp_path, capsys):
    """``growjax fit`` makes the rig's errors parameters of the model by default (``--rig-tangents``);
    ``--no-rig-tangents`` takes secants, relinearised where the data put the rig unless ``--no-relinearise``."""
    from growjax import calibration, cli

    seen = []

    def stop(*args, **kwargs):
        seen.append((kwargs.get("relinearise"), kwargs.get("rig_tangents")))
        raise ValueError("stopped before fitting")

    monkeypatch.setattr(calibration, "fit", stop)
    data = "src/growjax/data/datasets/synthetic_forward.csv"
    for extra in ([], ["--rig-tangents"], ["--no-rig-tangents"], ["--no-rig-tangents", "--no-relinearise"]):
        assert cli.main(["fit", data, "--out", str(tmp_path), "--quiet", *extra]) == 2
    assert seen == [(True, True), (True, True), (True, False), (False, False)]
    assert "stopped before fitting" in capsys.readouterr().err
