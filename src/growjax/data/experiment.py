"""Experiments as data: reading, validating and writing time series, and turning them into model inputs.

CSV format (UTF-8 text): a ``time_s`` column (strictly increasing, from 0 s on), a ``catheter_length_m`` column
(input; required unless the experiment had no catheter in contact: ``catheter=False``) and any of
``robot_length_m`` (measured), ``pressure_Pa`` (measured), ``pressure_demand_Pa`` (input, forward
drive), ``desired_length_m`` (input, inverse drive), ``syringe_displacement_m`` (measured: the syringes'
travel from full) and ``robot_flow_m3_s`` (measured: the flow into the robot at its inlet). A measured column
read as sparse (``read(..., sparse=...)``) may have empty cells: samples its sensor did not take. A column whose name nearly spells a known one (another case, a near spelling, the same words in
another order or unit) is an error naming both; any other column is not used (`Experiment.unused` names it).
The lab's MATLAB ``timeseries`` files are read with mat-io.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import math
import re
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from growjax.model.motor import step_schedule
from growjax.model.params import Parameters
from growjax.model.signals import Constant, Inputs, Sampled, StepSchedule, published_pulse

COLUMNS = (
    "robot_length_m",
    "pressure_Pa",
    "catheter_length_m",
    "pressure_demand_Pa",
    "desired_length_m",
    "syringe_displacement_m",
    "robot_flow_m3_s",
)
LENGTH_COLUMNS = ("robot_length_m", "catheter_length_m", "desired_length_m")  # never negative
DISPLACEMENT_COLUMNS = ("syringe_displacement_m",)  # a length that may dip below zero (noise about the full stop)
PRESSURE_COLUMNS = ("pressure_Pa", "pressure_demand_Pa")
MAX_PLAUSIBLE_LENGTH_M = 2.0  # a robot or catheter longer than this is almost surely in millimetres
MAX_PLAUSIBLE_FLOW_M3_S = 1e-2  # a flow above this (10 L/s) is almost surely in mm³/s or µL/s
MEASURED_COLUMNS = ("robot_length_m", "pressure_Pa", "syringe_displacement_m", "robot_flow_m3_s")
MIN_PLAUSIBLE_PEAK_PRESSURE_PA = 1e3  # a pressure record peaking below this (the membrane yields at ~8 kPa): kPa
NEAR_SPELLING = 0.85  # difflib's ratio from which a column name is a misspelling of a known one
UNITS = ("m", "mm", "cm", "um", "pa", "kpa", "mpa", "hpa", "bar", "mbar", "psi", "s", "ms", "us", "m3", "l", "ml")
MIN_SAMPLE_SPACING_S = 1e-9  # s: samples closer than this are one instant read twice


class ExperimentError(ValueError):
    """An experiment file or series that cannot be used as it is; the message names the problem."""


@dataclasses.dataclass(frozen=True)
class Experiment:
    """Time series of one experiment, SI units. ``series`` maps a column name to an array of shape (T,);
    ``unused`` names the file's columns that are not known (`COLUMNS`) and were not read."""

    time: np.ndarray
    series: dict
    source: str = ""
    unused: tuple[str, ...] = ()

    def __getitem__(self, name):
        return self.series[name]

    def __contains__(self, name):
        return name in self.series

    def window(self, t_end: float) -> Experiment:
        """The samples with time ≤ ``t_end`` (s)."""
        keep = self.time <= t_end + 1e-12
        return Experiment(self.time[keep], {k: v[keep] for k, v in self.series.items()}, self.source, self.unused)


def from_arrays(time, robot_length_m, pressure_Pa=None, **series) -> Experiment:
    """An experiment made of arrays: the measured length (m) (and pressure, Pa) at ``time`` (T,) s, and any other
    column of `COLUMNS` by name (SI).

    Raises:
        ExperimentError: a series that fails `validate_series`.
    """
    columns = {"robot_length_m": robot_length_m, "pressure_Pa": pressure_Pa, **series}
    columns = {k: np.asarray(v, float) for k, v in columns.items() if v is not None}
    time = np.asarray(time, float)
    validate_series(time, columns)
    return Experiment(time, columns)


def validate_series(time, series: dict, source: str = "", sparse=()) -> None:
    """Raise `ExperimentError` for NaN, unsorted, duplicate or negative times, millimetre or negative lengths and
    pressures in kPa. ``sparse``: measured columns whose samples may be missing (NaN: a sensor that reads
    rarely); their values present are checked as every column's."""
    where = f" in {source}" if source else ""
    time = np.asarray(time, float)
    if time.ndim != 1 or time.size < 2:
        raise ExperimentError(f"time_s{where} needs at least two samples")
    if not np.all(np.isfinite(time)):
        raise ExperimentError(
            f"time_s{where} contains NaN or infinite values (row {int(np.argmin(np.isfinite(time))) + 1})"
        )
    dt = np.diff(time)
    if np.any(dt < 0):
        raise ExperimentError(f"time_s{where} is not sorted: it decreases at t = {time[1:][dt < 0][0]} s")
    if np.any(dt < MIN_SAMPLE_SPACING_S):  # two readings of one instant: no noise model can tell them apart
        raise ExperimentError(
            f"time_s{where} has duplicate times (two samples within "
            f"{MIN_SAMPLE_SPACING_S:g} s, first at t = {time[1:][dt < MIN_SAMPLE_SPACING_S][0]} s)"
        )
    if time[0] < 0:
        raise ExperimentError(
            f"time_s{where} has negative times (the first: t = {time[0]:g} s, row 1): the model's time starts at 0 "
            "(the inputs' origin); shift the record to start at 0 or later"
        )
    for name, values in series.items():
        values = np.asarray(values, float)
        if values.shape != time.shape:
            raise ExperimentError(f"column {name}{where} has {values.size} values for {time.size} times")
        bad = np.isinf(values) if name in sparse else ~np.isfinite(values)
        if np.any(bad):
            raise ExperimentError(f"column {name}{where} contains NaN or infinite values (at t = {time[bad][0]} s)")
        _check_units(name, time[np.isfinite(values)], values[np.isfinite(values)], where)


def _check_units(name: str, time, values, where: str) -> None:
    """ExperimentError for a column's values (finite) that cannot be in its unit."""
    if values.size == 0:
        return
    if name in LENGTH_COLUMNS and np.any(values < 0):
        raise ExperimentError(f"column {name}{where} has negative lengths (at t = {time[values < 0][0]} s)")
    if name in LENGTH_COLUMNS + DISPLACEMENT_COLUMNS and np.max(np.abs(values)) > MAX_PLAUSIBLE_LENGTH_M:
        raise ExperimentError(
            f"column {name}{where} reaches {np.max(np.abs(values)):g} m: lengths look like millimetres; "
            "give them in metres (divide by 1000)"
        )
    if name == "robot_flow_m3_s" and np.max(np.abs(values)) > MAX_PLAUSIBLE_FLOW_M3_S:
        raise ExperimentError(
            f"column {name}{where} reaches {np.max(np.abs(values)):g} m³/s: flows look like mm³/s or µL/s; "
            "give them in m³/s (divide by 1e9)"
        )
    peak = float(np.max(np.abs(values)))
    if name in PRESSURE_COLUMNS and 0.0 < peak < MIN_PLAUSIBLE_PEAK_PRESSURE_PA:
        raise ExperimentError(
            f"column {name}{where} peaks at {peak:g} Pa: pressures look like kPa; give them in Pa (multiply by 1000)"
        )


def _words(name: str) -> tuple[frozenset, frozenset]:
    """(words, unit words) of a column name, lower case (``"Pressure_demand_kPa"``: ({pressure, demand}, {kpa}))."""
    tokens = [t for t in re.split(r"[^0-9a-z]+", name.lower()) if t]
    return frozenset(t for t in tokens if t not in UNITS), frozenset(t for t in tokens if t in UNITS)


def near_column(name: str) -> str | None:
    """The known column (``time_s`` or one of `COLUMNS`) that ``name`` nearly spells: the same name in another
    case, the same words in another order or unit, or a near spelling (difflib's ratio ≥ `NEAR_SPELLING`); None
    where it is known itself or near none."""
    known = ("time_s", *COLUMNS)
    if name in known:
        return None
    lower = {k.lower(): k for k in known}
    if name.lower() in lower:
        return lower[name.lower()]
    words = _words(name)[0]
    for k in known:
        if words and words == _words(k)[0]:
            return k
    close = difflib.get_close_matches(name.lower(), list(lower), n=1, cutoff=NEAR_SPELLING)
    return lower[close[0]] if close else None


def _check_header(path: Path, header: list) -> list:
    """The header's columns that are not used (neither known nor near one); ExperimentError naming a repeated
    column, one in millimetres, or one that nearly spells a known column absent from the file."""
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        raise ExperimentError(f"{path}: column {repeated[0]!r} appears more than once")
    for h in header:
        if h.endswith("_mm"):
            raise ExperimentError(f"{path}: column {h} is in millimetres; convert it to metres as {h[:-3]}_m")
    unused = []
    for h in header:
        if h == "time_s" or h in COLUMNS:
            continue
        near = near_column(h)
        if near is not None and near not in header:
            raise ExperimentError(
                f"{path}: column {h!r} is not a known column; did you mean {near!r}? (read in {_unit_of(near)})"
            )
        unused.append(h)
    return unused


def _unit_of(column: str) -> str:
    """The SI unit a known column is read in ("m", "Pa", "s", "m³/s")."""
    return "m³/s" if column.endswith("_m3_s") else column.rsplit("_", 1)[-1]


def read_csv(path, catheter: bool = True, sparse=()) -> Experiment:
    """Read an experiment CSV (see the module docstring), its units checked.

    Args:
        path: the file.
        catheter: True, the file must have a ``catheter_length_m`` column; False, the experiment had no catheter
            in contact (its length is taken as zero) and the file must not have one.
        sparse: measured columns whose empty cells are missing samples (NaN), not errors.

    Returns:
        The `Experiment`; its ``unused`` names the columns not read.

    Raises:
        ExperimentError: one line naming the file and the problem.
    """
    path = Path(path)
    if not path.exists():
        raise ExperimentError(f"no experiment file at {path}")
    header, rows = _read_rows(path)
    if "time_s" not in header:
        near = [h for h in header if near_column(h) == "time_s"]
        hint = f" (found {near[0]!r}: give the column as time_s, in seconds)" if near else ""
        raise ExperimentError(f"{path} has no time_s column{hint}; columns: {header}")
    unused = _check_header(path, header)
    known = [h for h in header if h in COLUMNS]
    if not known:
        raise ExperimentError(f"{path} has none of the columns {COLUMNS}; columns: {header}")
    for k, r in enumerate(rows):
        if len(r) != len(header):
            raise ExperimentError(f"{path}: data row {k + 1} has {len(r)} values for {len(header)} columns")
    try:
        data = np.array([[float(c) if c.strip() else math.nan for c in r] for r in rows], float)
    except ValueError as err:
        raise ExperimentError(f"{path}: a value is not a number ({err})") from None
    if data.ndim != 2 or data.shape[0] < 2:
        raise ExperimentError(f"{path} needs at least two rows of data")
    time = data[:, header.index("time_s")]
    series = {h: data[:, header.index(h)] for h in known}
    validate_series(time, series, str(path), sparse)
    _check_catheter("catheter_length_m" in series, catheter, str(path), "catheter_length_m column")
    return Experiment(time, series, str(path), tuple(unused))


def _read_rows(path: Path) -> tuple[list, list]:
    """(header, non-empty rows) of a CSV; ExperimentError for an empty, unreadable or binary file."""
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise ExperimentError(f"{path} is empty") from None
            return header, [r for r in reader if r and any(c.strip() for c in r)]
    except (UnicodeDecodeError, csv.Error):
        hint = ": give the folder holding kings_ts.mat and lin_c_ts.mat" if path.suffix.lower() == ".mat" else ""
        raise ExperimentError(f"{path} is not a text CSV (it holds binary data){hint}") from None
    except OSError as err:
        raise ExperimentError(f"cannot read {path}: {err.strerror or err}") from None


def _check_catheter(has: bool, catheter: bool, source: str, what: str) -> None:
    """ExperimentError unless ``source`` gives a catheter length (its ``what``, ``has``) exactly when ``catheter``."""
    said = "the experiment had no catheter in contact (--no-catheter; Python: catheter=False)"
    if catheter and not has:
        raise ExperimentError(f"{source} has no {what} (the catheter length, m): add it, or say {said}")
    if not catheter and has:
        raise ExperimentError(
            f"{source} gives the catheter length ({what}), but --no-catheter (Python: "
            "catheter=False) says the experiment had none: drop one or the other"
        )


def write_csv(path, time, series: dict) -> None:
    """Write an experiment CSV with ``time_s`` then the given columns."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(series)
    cols = [np.asarray(time, float)] + [np.asarray(series[n], float) for n in names]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", *names])
        for row in zip(*cols):
            w.writerow([repr(float(v)) for v in row])


def read_mat_timeseries(path, name: str | None = None):
    """(time s, values) of a MATLAB ``timeseries`` object in ``path`` (decoded with mat-io)."""
    import matio

    contents = matio.load_from_mat(str(path))
    keys = [k for k in contents if not k.startswith("__")]
    name = name or (keys[0] if len(keys) == 1 else None)
    if name is None or name not in contents:
        raise ExperimentError(f"{path}: say which variable to read, one of {keys}")
    props = contents[name].properties
    values = np.asarray(props["Data_"], float).ravel()
    time = np.asarray(props["TimeInfo"].properties["Time_"], float).ravel()
    if time.size != values.size:
        info = props["TimeInfo"].properties
        start, step = float(np.ravel(info["Start_"])[0]), float(np.ravel(info["Increment_"])[0])
        time = start + step * np.arange(values.size)
    return time, values


def read_mat_experiment(length_file, catheter_file=None) -> Experiment:
    """An experiment from the lab's ``kings_ts.mat`` (robot length) and ``lin_c_ts.mat`` (catheter length;
    None: no catheter in contact)."""
    t, length = read_mat_timeseries(length_file)
    series = {"robot_length_m": length}
    if catheter_file is not None:
        tc, cath = read_mat_timeseries(catheter_file)
        if tc.shape != t.shape or not np.allclose(tc, t):
            cath = np.interp(t, tc, cath)
        series["catheter_length_m"] = cath
    validate_series(t, series, str(length_file))
    return Experiment(t, series, str(length_file))


def read(path, catheter: bool = True, sparse=()) -> Experiment:
    """Read an experiment from a CSV, or from a folder holding kings_ts.mat and lin_c_ts.mat.

    ``catheter``: True, the experiment must give the catheter length (a ``catheter_length_m`` column, or
    lin_c_ts.mat in the folder); False, it had no catheter in contact (taken as zero) and must not give one.
    ``sparse``: measured columns of a CSV whose empty cells are missing samples (NaN), not errors.
    """
    path = Path(path)
    if path.is_dir():
        length_file, catheter_file = path / "kings_ts.mat", path / "lin_c_ts.mat"
        if not length_file.is_file():
            raise ExperimentError(f"{path} has no {length_file.name} (the robot length)")
        _check_catheter(catheter_file.is_file(), catheter, str(path), catheter_file.name)
        return read_mat_experiment(length_file, catheter_file if catheter else None)
    return read_csv(path, catheter, sparse)


def demand_steps(params: Parameters, desired_length, steps_per_metre: float | None = None):
    """Stepper demand (steps, non-integer) for a desired robot length (m): x_s = A_r L/(n A_s), × steps/m (eq. 2)."""
    pump, motor, robot = params.pump, params.motor, params.robot
    if steps_per_metre is None:
        steps_per_metre = (2 * math.pi / float(motor.step_angle)) / float(pump.lead)
    gain = float(robot.area) / (pump.n_syringes * float(pump.syringe_area))
    return np.asarray(desired_length, float) * gain * steps_per_metre


def to_inputs(exp: Experiment, drive: str, params: Parameters, t0: float = 0.001, t1: float = 10.0) -> Inputs:
    """Model inputs from an experiment.

    Forward drive: ``pressure_demand_Pa`` if present, else the published 0/150 kPa pulse.
    Inverse drive: ``desired_length_m`` if present, else the measured ``robot_length_m``
    (as in the shipped model), converted to steps and run through the position controller.
    An experiment without ``catheter_length_m`` (read with ``catheter=False``) has the catheter at zero.
    """
    t = jnp.asarray(exp.time)
    catheter = Sampled(t, jnp.asarray(exp["catheter_length_m"])) if "catheter_length_m" in exp else Constant(0.0)
    if drive == "forward":
        demand = (
            Sampled(t, jnp.asarray(exp["pressure_demand_Pa"])) if "pressure_demand_Pa" in exp else published_pulse()
        )
        return Inputs(catheter_length=catheter, pressure_demand=demand)
    if drive != "inverse":
        raise ExperimentError(f"drive must be 'forward' or 'inverse', got {drive!r}")
    for col in ("desired_length_m", "robot_length_m"):
        if col in exp:
            desired = exp[col]
            break
    else:
        raise ExperimentError(
            f"{exp.source or 'experiment'}: the inverse drive needs a desired_length_m (or robot_length_m) column"
        )
    steps = demand_steps(params, desired)
    times, counts = step_schedule(steps, exp.time, float(params.motor.controller_rate), t0, t1)
    return Inputs(
        catheter_length=catheter,
        pressure_demand=Constant(0.0),
        steps=StepSchedule(jnp.asarray(times), jnp.asarray(counts)),
        desired_length=Sampled(t, jnp.asarray(desired)),
    )


INTERPOLATED_SHARE = 0.9  # a record is interpolated when this share of its second differences vanish
VERTEX_FRACTION = 1e-3  # a vertex bends the record by more than this share of its sharpest bend


def informative_samples(values) -> np.ndarray:
    """Which samples (T,) bool of a record ``values`` (T,) carry its information.

    A record digitised at keyframes and linearly interpolated to a fixed rate is piecewise linear: its
    second differences vanish (to rounding) between keyframes. Its interpolated samples are fixed by the
    keyframes, so they carry nothing beyond them, and a likelihood over every sample would count each
    keyframe many times. For such a record (at least :data:`INTERPOLATED_SHARE` of its second differences
    below 1e-4 of the largest) the informative samples are the vertices (second difference above
    :data:`VERTEX_FRACTION` of the largest) and the two ends; for any other record, every sample.
    """
    y = np.asarray(values, float)
    keep = np.ones(y.size, bool)
    if y.size < 5:
        return keep
    bend = np.abs(np.diff(y, 2))
    top = float(np.max(bend))
    if top == 0.0 or np.mean(bend < 1e-4 * top) < INTERPOLATED_SHARE:
        return keep
    keep[:] = False
    keep[1:-1] = bend > VERTEX_FRACTION * top
    keep[0] = keep[-1] = True
    return keep


def shared_experiment_dir() -> Path | None:
    """The public MAMMOBOT experiment beside the checkout (``../shared/data/mammobot``), if present."""
    here = Path(__file__).resolve()
    for parent in [Path.cwd(), *here.parents]:
        cand = parent.parent / "shared" / "data" / "mammobot"
        if (cand / "experiment.csv").exists():
            return cand
    return None


__all__ = [
    "COLUMNS",
    "MEASURED_COLUMNS",
    "Experiment",
    "ExperimentError",
    "demand_steps",
    "from_arrays",
    "informative_samples",
    "near_column",
    "read",
    "read_csv",
    "read_mat_experiment",
    "read_mat_timeseries",
    "shared_experiment_dir",
    "to_inputs",
    "validate_series",
    "write_csv",
]
