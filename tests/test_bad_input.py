"""Bad input, case by case: the table below is what growjax refuses and how it says so.

Each row of `REFUSED` is a command line, its exit status (2: bad input) and the key words of the one line it prints
on stderr, which names the file or option and the problem. A refused input is refused before any compile or
simulation (no program traced, nothing written under ``--out``). Each row of `NOTED` is an input that is usable as
it is: one note on stderr says what growjax makes of it, and the command goes on to its work.

Rows are written in the command-line vocabulary to come; a flag the parser still spells otherwise is translated by
`FLAGS`, so that a rename is a one-line edit there.
"""

import dataclasses
import os
import shlex

import jax
import numpy as np
import pytest

import growjax
from growjax import cli
from growjax.data import experiment as ex

# The vocabulary to come → the current parser's spelling (rows marked "new name" use them; empty once renamed).
FLAGS: dict = {}

ROOT = hasattr(os, "geteuid") and os.geteuid() == 0  # permissions do not bind root: those rows are skipped


def spelled(text: str) -> str:
    """``text`` with each flag of `FLAGS` spelled as the current parser spells it."""
    for new, current in FLAGS.items():
        text = text.replace(new, current)
    return text


@dataclasses.dataclass(frozen=True)
class Case:
    """One row: ``line`` (the command line after ``growjax``, files as ``{name}`` of `files`), the exit status and
    the words the one line on stderr holds."""

    line: str
    status: int
    words: tuple[str, ...]
    as_root: bool = True  # False: permissions the root user is not held to


def case(line: str, status: int, *words: str, as_root: bool = True) -> Case:
    return Case(line, status, words, as_root)


REFUSED = [
    # -- DATA: values ---------------------------------------------------------------------------------------------
    case("simulate {nan}", 2, "nan.csv", "robot_length_m", "NaN"),
    case("simulate {inf}", 2, "inf.csv", "catheter_length_m", "infinite"),
    case("simulate {unsorted}", 2, "unsorted.csv", "not sorted", "t = 0.015"),
    case("simulate {duplicate}", 2, "duplicate.csv", "duplicate times"),
    case("simulate {negative}", 2, "negative.csv", "negative times", "t = -1.5 s"),
    case("fit {negative}", 2, "negative.csv", "negative times"),
    case("simulate {single}", 2, "single.csv", "at least two rows"),
    case("simulate {empty}", 2, "empty.csv", "is empty"),
    case("simulate {header_only}", 2, "header_only.csv", "at least two rows"),
    case("simulate {not_a_number}", 2, "not_a_number.csv", "not a number"),
    case("simulate {ragged}", 2, "ragged.csv", "data row 2 has 2 values for 4 columns"),
    case("simulate {binary}", 2, "binary.csv", "not a text CSV"),
    # -- DATA: units (the reader's plausibility checks) -----------------------------------------------------------
    case("simulate {lengths_in_mm}", 2, "lengths_in_mm.csv", "robot_length_m", "millimetres"),
    case("simulate {mm_column}", 2, "mm_column.csv", "robot_length_mm", "millimetres"),
    case("simulate {demand_in_kpa}", 2, "demand_in_kpa.csv", "pressure_demand_Pa", "look like kPa"),
    case("fit {pressure_in_kpa}", 2, "pressure_in_kpa.csv", "pressure_Pa", "look like kPa"),
    # -- DATA: columns ----------------------------------------------------------------------------------------------
    case("simulate {no_time}", 2, "no_time.csv", "no time_s column", "'time'"),
    case("simulate {no_catheter}", 2, "no_catheter.csv", "catheter_length_m", "--no-catheter"),
    case("simulate {good} --no-catheter", 2, "good.csv gives the catheter length", "--no-catheter"),
    case("simulate {demand_lower_case}", 2, "'pressure_demand_pa'", "did you mean 'pressure_demand_Pa'"),
    case("simulate {demand_words_swapped}", 2, "'demand_pressure_Pa'", "did you mean 'pressure_demand_Pa'"),
    case("fit {pressure_kpa_named}", 2, "'pressure_kPa'", "did you mean 'pressure_Pa'", "read in Pa"),
    case("fit {length_misspelt}", 2, "'robot_lenght_m'", "did you mean 'robot_length_m'"),
    case("simulate {catheter_upper_case}", 2, "'Catheter_Length_m'", "did you mean 'catheter_length_m'"),
    case("simulate {repeated_column}", 2, "repeated_column.csv", "'robot_length_m' appears more than once"),
    case("simulate {demand_only} --drive inverse", 2, "demand_only.csv", "inverse drive needs a desired_length_m"),
    case("fit {demand_only}", 2, "demand_only.csv", "no robot_length_m column to fit"),
    # -- DATA: where it is ------------------------------------------------------------------------------------------
    case("simulate {missing}", 2, "no experiment file at", "missing.csv"),
    case("simulate {empty_folder}", 2, "empty_folder", "no kings_ts.mat"),
    case("simulate {late}", 2, "late.csv", "20–22 s", "do not overlap"),
    case("simulate mammobot", 2, "could not download", "--data-dir"),
    case("simulate mammobot --data-dir {empty_folder}", 2, "no file kings_ts.mat", "empty_folder"),
    case("simulate {good} --data-dir {empty_folder}", 2, "--data-dir applies to a named data set", "good.csv"),
    # -- parameters -------------------------------------------------------------------------------------------------
    case("simulate {good} --param Y=-1", 2, "--param Y=-1", "robot.yield_pressure", "physical range"),
    case("simulate {good} --param Yield=9000", 2, "--param Yield: unknown parameter", "growjax params"),
    case("simulate {good} --param Y", 2, "--param expects NAME=VALUE", "'Y'"),
    case("simulate {good} --param Y=soft", 2, "--param Y", "'soft' is not a number"),
    case("fit {good} --free Yield", 2, "--free Yield: unknown parameter"),
    case("fit {good} --free Y@robot", 2, "--free Y@robot", "applies to several experiments"),
    case("fit {manifest} --free Y@planet", 2, "--free Y@planet", "unknown scope 'planet'"),
    case("fit {good} --tolerance Kp=abc", 2, "--tolerance Kp", "'abc' is not a number"),
    case("fit {good} --tolerance Kp=1.5", 2, "--tolerance Kp=1.5", "[0, 1)"),
    case("fit {good} --tolerance Kpp=0.1", 2, "--tolerance Kpp: unknown parameter", "did you mean 'Kp'"),
    case("posterior {good} --hierarchical Yield", 2, "--hierarchical Yield: unknown parameter"),
    case("design {good} --for Yield", 2, "--for Yield: unknown parameter"),
    case("discover {good} --candidates fluid_leek", 2, "--candidates", "unknown effect 'fluid_leek'", "fluid_leak"),
    # -- counts, ranges, spans --------------------------------------------------------------------------------------
    case("sweep {good} --sets -1", 2, "--sets", "must be at least 1, got -1"),
    case("sweep {good} --sobol-points 100", 2, "--sobol-points", "power of 2"),
    case("sweep {good} --range Y=15000:5000", 2, "--range Y=15000:5000", "LOW < HIGH"),
    case("sweep {good} --range Y=-5000:5000", 2, "--range robot.yield_pressure=-5000:5000", "physical range"),
    case("sweep {good} --range Yield=1:2", 2, "--range Yield=1:2", "unknown parameter"),
    case("sweep {good} --range Y=a:b", 2, "--range Y", "not numbers"),
    case("sweep {good} --range Y=1:2:sqrt", 2, "--range Y", "LOW:HIGH or LOW:HIGH:log"),
    case("sweep {good} --coordinator host:1234", 2, "--coordinator, --num-processes and --process-id go together"),
    case("sweep {good} --resume {missing_folder}", 2, "--resume", "no such folder"),
    case("fit {good} --starts 0", 2, "--starts", "must be at least 1, got 0"),
    case("fit {good} --t-start 20", 2, "--t-start 20", "must lie before --t-end"),
    case("design {good} --t-start 10", 2, "--t-start 10 s", "must lie before --t-end 10 s"),
    case("posterior {good} --chains 0", 2, "--chains", "must be at least 1"),
    case("posterior {good} --predict {good}", 2, "--predict", "--hierarchical"),
    case("control {good} --tuning-draws 0", 2, "--tuning-draws", "must be at least 1"),
    case("control {good} --rtol 1e-6", 2, "unrecognized arguments: --rtol"),
    case("control {good} --robust {missing_posterior}", 2, "--robust", "missing.nc", "no such file"),
    case("design {good} --size 1e-3", 2, "--size", "--discriminate"),
    case("simulate {good} --t-end -1", 2, "--t-end", "must be a positive number"),
    case("simulate {good} --drive sideways", 2, "--drive", "invalid choice: 'sideways'"),
    # -- manifests --------------------------------------------------------------------------------------------------
    case("fit {manifest_unknown_key}", 2, "manifest_unknown_key.toml", "unknown key(s) ['colour']"),
    case("fit {manifest_missing_file}", 2, "manifest_missing_file.toml", "file nope.csv not found"),
    case("fit {manifest_unknown_rig}", 2, "manifest_unknown_rig.toml", "unknown rig 'bench-2'"),
    case("fit {manifest_unknown_sensor}", 2, "manifest_unknown_sensor.toml", "unknown sensor(s) ['flow']"),
    case("fit {manifest_bad_window}", 2, "manifest_bad_window.toml", "window must be [t_start, t_end]"),
    case("fit {manifest_not_toml}", 2, "manifest_not_toml.toml", "not a TOML manifest"),
    case("fit {manifest_empty}", 2, "manifest_empty.toml", "no [[experiment]] entries"),
    case("fit {manifest} {good}", 2, "a manifest (.toml) describes the whole set: give it alone"),
    case("fit {missing_manifest}", 2, "manifest", "missing.toml not found"),
    # -- outputs ----------------------------------------------------------------------------------------------------
    case("simulate {good} --out {a_file}", 2, "--out", "a_file.txt", "names a folder", "is a file"),
    case("simulate {good} --out {a_file}/run", 2, "--out", "a_file.txt is a file, not a folder"),
    case("simulate {good} --json {a_folder}", 2, "--json", "names a file", "is a folder"),
    case("simulate {good} --json {a_file}/s.json", 2, "--json", "a_file.txt is a file, not a folder"),
    case("params --json {a_folder}", 2, "--json", "is a folder"),
    case("simulate {good} --out {read_only_folder}", 2, "--out", "not writable", as_root=False),
    case("simulate {good} --out {read_only_folder}/run", 2, "--out", "cannot write in", as_root=False),
    case("simulate {good} --json {read_only_file}", 2, "--json", "read_only.json", "not writable", as_root=False),
    case("fit {good} --json {read_only_folder}/s.json", 2, "--json", "cannot write in", as_root=False),
]

NOTED = [
    case("simulate {extra_column}", 0, "note", "'temperature_C'", "not used"),
    case("simulate {no_demand}", 0, "note", "no pressure_demand_Pa column", "published 0/150 kPa pulse train"),
    case("simulate {good} --t-end 12", 0, "note", "0.01–10 s", "shrunk to 0.001–10 s"),
    case("simulate {short}", 0, "note", "0.01–3 s", "shrunk to 0.001–3 s"),
]


def _write(path, header: str, rows) -> str:
    path.write_text(header + "\n" + "".join(",".join(str(v) for v in r) + "\n" for r in rows))
    return str(path)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    """The files the rows name: experiments good and bad, manifests, folders, read-only places."""
    d = tmp_path_factory.mktemp("bad_input")
    t = np.round(np.arange(1, 1001) * 0.01, 10)  # 0.01–10 s
    length, catheter, demand = 0.01 + 0.002 * t, np.full(t.size, 0.004), np.where(t > 1.0, 150e3, 0.0)
    full = "time_s,robot_length_m,catheter_length_m,pressure_demand_Pa"
    rows = list(zip(t, length, catheter, demand))
    f = {"good": _write(d / "good.csv", full, rows)}

    def bad(name, header=full, changed=None, upto=None):
        r = [list(x) for x in rows[:upto]]
        for (i, j), v in (changed or {}).items():
            r[i][j] = v
        f[name] = _write(d / f"{name}.csv", header, r)

    bad("nan", changed={(5, 1): "nan"})
    bad("inf", changed={(7, 2): "inf"})
    bad("unsorted", changed={(3, 0): 0.015})
    bad("duplicate", changed={(3, 0): 0.03})
    f["negative"] = _write(d / "negative.csv", full, [(x - 1.51, *r[1:]) for x, r in zip(t, rows)])
    bad("single", upto=1)
    (d / "empty.csv").write_text("")
    f["empty"] = str(d / "empty.csv")
    bad("header_only", upto=0)
    bad("not_a_number", changed={(4, 1): "ten"})
    f["ragged"] = _write(d / "ragged.csv", full, [rows[0], rows[1][:2], *rows[2:]])
    (d / "binary.csv").write_bytes(bytes(range(128, 256)))
    f["binary"] = str(d / "binary.csv")
    f["lengths_in_mm"] = _write(d / "lengths_in_mm.csv", full, [(x, 1e3 * y, c, p) for x, y, c, p in rows])
    bad("mm_column", header=full.replace("robot_length_m", "robot_length_mm"))
    f["demand_in_kpa"] = _write(d / "demand_in_kpa.csv", full, [(x, y, c, p / 1e3) for x, y, c, p in rows])
    f["pressure_in_kpa"] = _write(
        d / "pressure_in_kpa.csv",
        "time_s,robot_length_m,catheter_length_m,pressure_Pa",
        [(x, y, c, 9.1) for x, y, c, _ in rows],
    )
    bad("no_time", header=full.replace("time_s", "time"))
    bad("no_catheter", header="time_s,robot_length_m,comment,pressure_demand_Pa")
    bad("demand_lower_case", header=full.replace("pressure_demand_Pa", "pressure_demand_pa"))
    bad("demand_words_swapped", header=full.replace("pressure_demand_Pa", "demand_pressure_Pa"))
    bad("pressure_kpa_named", header=full.replace("pressure_demand_Pa", "pressure_kPa"))
    bad("length_misspelt", header=full.replace("robot_length_m", "robot_lenght_m"))
    bad("catheter_upper_case", header=full.replace("catheter_length_m", "Catheter_Length_m"))
    bad("repeated_column", header=full.replace("catheter_length_m", "robot_length_m"))
    bad("demand_only", header="time_s,syringe_displacement_m,catheter_length_m,pressure_demand_Pa")
    f["late"] = _write(d / "late.csv", full, [(x + 20.0, *r[1:]) for x, r in zip(np.linspace(0, 2, 5), rows)])
    f["extra_column"] = _write(d / "extra_column.csv", full + ",temperature_C", [(*r, 21.5) for r in rows])
    f["short"] = _write(d / "short.csv", full, rows[:300])
    f["no_demand"] = _write(d / "no_demand.csv", "time_s,robot_length_m,catheter_length_m", [r[:3] for r in rows])
    f["missing"] = str(d / "missing.csv")
    f["missing_folder"] = str(d / "missing_folder")
    f["missing_posterior"] = str(d / "missing.nc")
    f["missing_manifest"] = str(d / "missing.toml")
    for name in ("empty_folder", "a_folder", "read_only_folder"):
        (d / name).mkdir()
        f[name] = str(d / name)
    (d / "a_file.txt").write_text("not a folder\n")
    f["a_file"] = str(d / "a_file.txt")
    (d / "read_only.json").write_text("{}\n")
    f["read_only_file"] = str(d / "read_only.json")
    manifests = {
        "manifest": '[[experiment]]\nfile = "good.csv"\nrobot = "a"\n\n[[experiment]]\nfile = "no_demand.csv"\n'
        'robot = "b"\n',
        "manifest_unknown_key": '[[experiment]]\nfile = "good.csv"\ncolour = "red"\n',
        "manifest_missing_file": '[[experiment]]\nfile = "nope.csv"\n',
        "manifest_unknown_rig": '[rig.bench]\n\n[[experiment]]\nfile = "good.csv"\nrig = "bench-2"\n',
        "manifest_unknown_sensor": '[[experiment]]\nfile = "good.csv"\nsensors = ["length", "flow"]\n',
        "manifest_bad_window": '[[experiment]]\nfile = "good.csv"\nwindow = [2.0, 1.0]\n',
        "manifest_not_toml": "[[experiment]\nfile = good.csv\n",
        "manifest_empty": "[defaults]\ndrive = 'forward'\n",
    }
    for name, text in manifests.items():
        (d / f"{name}.toml").write_text(text)
        f[name] = str(d / f"{name}.toml")
    os.chmod(d / "read_only_folder", 0o555)
    os.chmod(d / "read_only.json", 0o444)
    yield f
    os.chmod(d / "read_only_folder", 0o755)


@pytest.fixture(autouse=True)
def offline(monkeypatch, tmp_path):
    """No download: the network is unreachable, the data cache empty and no local copy named."""
    import pooch

    def unreachable(url, *args, **kwargs):
        raise ConnectionError(f"network unreachable: {url}")

    monkeypatch.setattr(pooch, "retrieve", unreachable)
    monkeypatch.setenv("GROWJAX_DATA_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("GROWJAX_DATA_DIR", raising=False)


@pytest.fixture
def traced():
    """The durations, s, of the programs JAX traces meanwhile (a model's solve takes seconds to trace)."""
    seen = []

    def listen(event, duration, **_):
        if event == "/jax/core/compile/jaxpr_trace_duration":
            seen.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listen)
    yield seen
    jax.monitoring.unregister_event_duration_listener(listen)


def run(argv) -> int:
    """``growjax ARGV`` in this process: its exit status (the parser's own exit included)."""
    try:
        return cli.main(argv)
    except SystemExit as stop:
        return stop.code


def command_line(row: Case, files: dict, out) -> list[str]:
    argv = [spelled(a) for a in shlex.split(row.line.format(**files))]
    return argv if "--out" in argv or argv[0] in ("params", "effects") else [*argv, "--out", str(out)]


@pytest.mark.parametrize("row", REFUSED, ids=[r.line.split("{")[0].strip() + " " + r.words[0] for r in REFUSED])
def test_bad_input_is_refused_with_one_line_before_any_work(row, files, tmp_path, capsys, traced):
    if ROOT and not row.as_root:
        pytest.skip("the root user is not held to permissions")
    out = tmp_path / "out"
    status = run(command_line(row, files, out))
    err = capsys.readouterr().err.strip().splitlines()
    assert status == row.status, (row.line, err)
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert err[0].startswith("growjax ") and all(spelled(w) in err[0] for w in row.words), (row.words, err[0])
    assert not out.exists()  # nothing written
    assert max(traced, default=0.0) < 0.5, f"a program was traced for {max(traced):.1f} s before the refusal"


class _Reached(Exception):
    """Raised by a stand-in for the simulation: the command accepted its input and went on to its work."""


@pytest.mark.parametrize("row", NOTED, ids=[r.words[1] for r in NOTED])
def test_usable_input_is_noted_in_one_line_and_the_command_goes_on(row, files, tmp_path, capsys, monkeypatch):
    def reached(*args, **kwargs):
        raise _Reached

    monkeypatch.setattr(growjax, "simulate", reached)
    with pytest.raises(_Reached):
        cli.main(command_line(row, files, tmp_path / "out"))
    err = capsys.readouterr().err.strip().splitlines()
    notes = [line for line in err if line.startswith("growjax ")]  # the rest is progress ("simulate: …")
    assert len(notes) == 1 and all(w in notes[0] for w in row.words), err


def test_the_table_covers_every_workflow_command_and_forty_cases():
    commands = {r.line.split()[0] for r in REFUSED}
    assert {"simulate", "sweep", "fit", "posterior", "discover", "control", "design", "params"} <= commands
    assert len(REFUSED) + len(NOTED) >= 40


def test_near_column_names_the_known_column_a_name_nearly_spells():
    """Another case, the same words in another order or unit, a near spelling: the known column; a name near
    none (or a known one): None."""
    assert ex.near_column("pressure_demand_pa") == "pressure_demand_Pa"
    assert ex.near_column("Demand_Pressure_kPa") == "pressure_demand_Pa"
    assert ex.near_column("robot_len_m") == "robot_length_m"
    assert ex.near_column("robot_flow") == "robot_flow_m3_s"
    assert ex.near_column("Syringe_Displacement_mm") == "syringe_displacement_m"
    assert ex.near_column("Time") == "time_s"
    for far in ("temperature_C", "comment", "valve_pressure_Pa", "robot_length_m"):
        assert ex.near_column(far) is None, far


def test_a_column_near_one_the_file_also_has_is_not_used_not_refused(tmp_path):
    """A file with pressure_Pa beside a near name (pressure_kPa): the near one is another column, not a misspelling."""
    path = tmp_path / "two.csv"
    path.write_text(
        "time_s,robot_length_m,catheter_length_m,pressure_Pa,pressure_kPa\n0.1,0.01,0.004,9000,9\n0.2,0.01,0.004,9100,9.1\n"
    )
    exp = ex.read(path)
    assert exp.unused == ("pressure_kPa",) and "pressure_Pa" in exp
    np.testing.assert_allclose(exp["pressure_Pa"], [9000.0, 9100.0])
