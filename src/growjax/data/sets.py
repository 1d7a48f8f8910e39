"""Several experiments in one calibration: which robot and which rig each one ran on, its inputs and sensors.

An :class:`ExperimentSet` holds :class:`Run` s. Each run keeps its own series (length; pressure where recorded),
drive, window and inputs; it names the **robot** (one membrane: its yield pressure and growth law) and the
**rig** (the pump, controller, hoses and tank: the parameters the tolerance budget covers) it ran on. A fit or a
posterior of a set then gives a free parameter one value per robot, per rig, per run or one for all (its
:class:`Scope`), and one set of rig errors per rig, shared by every run on it.

A set is read from a list of files (one robot on one rig) or from a TOML manifest::

    [defaults]                # optional: any per-experiment key
    drive = "forward"
    rig = "bench"

    [[experiment]]
    file = "pulse_a.csv"      # relative to the manifest
    robot = "membrane-1"
    window = [0.0, 10.0]      # s, optional
    sensors = ["length", "pressure"]   # default: the length alone

    [rig.bench]               # optional: a rig's fixed values (SI, names as in `growjax params`)
    parameters = { "tank.length" = 0.1 }

    [robot.membrane-1]        # optional: a robot's fixed values
    parameters = { "robot.catheter_friction" = 0.05 }

Where ``[rig.*]`` or ``[robot.*]`` tables are given, an experiment naming one not declared is an error.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from growjax.data import experiment as ex
from growjax.data.experiment import Experiment, ExperimentError
from growjax.model import params as gp

__all__ = ["SCOPES", "SENSORS", "ExperimentSet", "Run", "Scope", "read"]

SCOPES = ("shared", "robot", "rig", "experiment")
SENSORS = ("length", "pressure")
_KEYS = {"file", "name", "drive", "robot", "rig", "window", "sensors", "parameters"}


@dataclasses.dataclass(frozen=True)
class Run:
    """One experiment of a set: its series (SI), drive, robot, rig, scored window (s) and sensors.

    Attributes:
        name: the run's name, unique in its set.
        experiment: its series (`growjax.data.experiment.Experiment`).
        drive: ``"forward"`` or ``"inverse"``.
        robot: the robot (membrane) it ran.
        rig: the rig (pump, controller, hoses, tank) it ran on.
        window: (t_start, t_end) s of the samples scored, or None (the configuration's span).
        sensors: the series scored: ``"length"``, and ``"pressure"`` where recorded.
        parameters: {name: value, SI} fixed for this run on top of ``defaults`` (the robot's and the rig's
            declared values included).
        defaults: the parameters ``parameters`` are set on; None: its drive's reference.
        inputs: the model's inputs (`growjax.Inputs`); None: made from the experiment's columns
            (`growjax.data.experiment.to_inputs`).
    """

    name: str
    experiment: Experiment
    drive: str = "forward"
    robot: str = "robot"
    rig: str = "rig"
    window: tuple[float, float] | None = None
    sensors: tuple[str, ...] = ("length",)
    parameters: dict = dataclasses.field(default_factory=dict)
    defaults: gp.Parameters | None = dataclasses.field(default=None, compare=False, repr=False)
    inputs: object = dataclasses.field(default=None, compare=False, repr=False)

    def base(self, growth_law: str = "reference") -> gp.Parameters:
        """The run's parameters: ``defaults`` (else its drive's reference with ``growth_law``) with
        ``parameters`` set."""
        base = self.defaults if self.defaults is not None else gp.reference(self.drive, growth_law=growth_law)
        return gp.replace(base, **self.parameters) if self.parameters else base

    def model_inputs(self, base: gp.Parameters, t0: float, t1: float):
        """The model's inputs for the parameters ``base`` over [t0, t1] s: ``inputs`` where given, else made from
        the experiment's columns."""
        if self.inputs is not None:
            return self.inputs
        return ex.to_inputs(self.experiment, self.drive, base, t0, t1)

    @property
    def times(self) -> np.ndarray:
        return self.experiment.time

    @property
    def length(self) -> np.ndarray:
        return self.experiment["robot_length_m"]

    @property
    def pressure(self) -> np.ndarray | None:
        return self.experiment["pressure_Pa"] if "pressure" in self.sensors else None


@dataclasses.dataclass(frozen=True)
class ExperimentSet:
    """Runs calibrated together. Iterates over its :class:`Run` s; :attr:`robots` and :attr:`rigs` in order of
    first appearance."""

    runs: tuple[Run, ...]

    def __post_init__(self):
        if not self.runs:
            raise ExperimentError("an experiment set needs at least one experiment")
        names = [r.name for r in self.runs]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ExperimentError(f"experiment names must be unique in a set, {dup} repeat")

    def __iter__(self):
        return iter(self.runs)

    def __len__(self) -> int:
        return len(self.runs)

    @property
    def robots(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(r.robot for r in self.runs))

    @property
    def rigs(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(r.rig for r in self.runs))

    def group_of(self, scope: str) -> list[str]:
        """Per run, the key of its copy of a parameter of ``scope`` (a robot, a rig, its own name, or 'all')."""
        return [{"shared": "all", "robot": r.robot, "rig": r.rig, "experiment": r.name}[scope] for r in self.runs]

    @classmethod
    def single(
        cls,
        experiment: Experiment,
        *,
        name: str = "experiment",
        drive: str = "forward",
        robot: str = "robot",
        rig: str = "rig",
        window: tuple[float, float] | None = None,
        sensors: Sequence[str] | None = None,
        parameters: dict | None = None,
        defaults: gp.Parameters | None = None,
        inputs=None,
    ) -> ExperimentSet:
        """The set of one experiment (a fit, posterior or discovery of one run takes it).

        Args:
            experiment: its series; a measured ``robot_length_m`` is required.
            name, drive, robot, rig, window, parameters, defaults, inputs: as `Run`'s.
            sensors: the series scored; None: the length, and the pressure where the experiment records it.

        Raises:
            ExperimentError: a bad drive, sensor, window or parameter, naming it.
        """
        used = tuple(sensors) if sensors is not None else SENSORS if "pressure_Pa" in experiment else ("length",)
        run = _run(name, experiment, drive, robot, rig, window, used, dict(parameters or {}), name, defaults)
        return cls((dataclasses.replace(run, inputs=inputs),))

    @classmethod
    def from_files(
        cls,
        paths: Iterable,
        drive: str = "forward",
        robot: str = "robot",
        rig: str = "rig",
        window: tuple[float, float] | None = None,
        sensors: Sequence[str] | None = None,
        parameters: dict | None = None,
        catheter: bool = True,
    ) -> ExperimentSet:
        """Runs from experiment files (CSV, or MATLAB folders): one robot on one rig. ``sensors`` None: the length,
        and the pressure where a file records it."""
        runs = []
        for path in paths:
            exp = _read(Path(path), catheter)
            used = (
                tuple(sensors)
                if sensors is not None
                else (("length", "pressure") if "pressure_Pa" in exp else ("length",))
            )
            runs.append(
                _run(
                    Path(path).stem if Path(path).suffix else Path(path).name,
                    exp,
                    drive,
                    robot,
                    rig,
                    window,
                    used,
                    dict(parameters or {}),
                    str(path),
                )
            )
        return cls(tuple(_unique_names(runs)))

    @classmethod
    def from_manifest(cls, path, catheter: bool = True) -> ExperimentSet:
        """The set a TOML manifest describes (see the module docstring); ExperimentError naming the manifest, the
        experiment and the problem."""
        path = Path(path)
        try:
            doc = tomllib.loads(path.read_text())
        except FileNotFoundError:
            raise ExperimentError(f"manifest {path} not found") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise ExperimentError(f"{path}: not a TOML manifest ({err})") from None
        entries = doc.get("experiment")
        if not isinstance(entries, list) or not entries:
            raise ExperimentError(f"{path}: no [[experiment]] entries")
        defaults = doc.get("defaults", {})
        declared = {kind: doc.get(kind) for kind in ("rig", "robot")}
        runs = []
        for k, entry in enumerate(entries):
            spec = {**defaults, **entry}
            label = f"{path}: experiment {spec.get('name', spec.get('file', k + 1))!r}"
            unknown = set(spec) - _KEYS
            if unknown:
                raise ExperimentError(f"{label}: unknown key(s) {sorted(unknown)} (known: {sorted(_KEYS)})")
            if "file" not in spec:
                raise ExperimentError(f"{label}: no file given")
            file = (path.parent / spec["file"]).resolve()
            if not file.exists():
                raise ExperimentError(f"{label}: file {spec['file']} not found (looked in {path.parent})")
            values = {}
            for kind in ("rig", "robot"):
                name = str(spec.get(kind, kind))
                table = declared[kind]
                if table is not None:
                    if name not in table:
                        raise ExperimentError(f"{label}: unknown {kind} {name!r} (declared: {sorted(table)})")
                    values.update(table[name].get("parameters", {}))
            values.update(spec.get("parameters", {}))
            exp = _read(file, catheter)
            sensors = tuple(spec.get("sensors", ("length",)))
            window = tuple(float(w) for w in spec["window"]) if "window" in spec else None
            name = str(spec.get("name", Path(spec["file"]).stem))
            runs.append(
                _run(
                    name,
                    exp,
                    str(spec.get("drive", "forward")),
                    str(spec.get("robot", "robot")),
                    str(spec.get("rig", "rig")),
                    window,
                    sensors,
                    values,
                    label,
                )
            )
        return cls(tuple(runs))


def read(paths: Sequence, **options) -> ExperimentSet:
    """An :class:`ExperimentSet` from one TOML manifest, or from experiment files (one robot on one rig)."""
    paths = [Path(p) for p in paths]
    if len(paths) == 1 and paths[0].suffix.lower() == ".toml":
        return ExperimentSet.from_manifest(paths[0], catheter=options.get("catheter", True))
    if any(p.suffix.lower() == ".toml" for p in paths):
        raise ExperimentError("a manifest (.toml) describes the whole set: give it alone")
    return ExperimentSet.from_files(paths, **options)


def _read(path: Path, catheter: bool) -> Experiment:
    if not path.exists():
        raise ExperimentError(f"{path} not found")
    return ex.read(path, catheter=catheter)


def _run(name, exp: Experiment, drive, robot, rig, window, sensors, parameters, label, defaults=None) -> Run:
    """A `Run`, checked: drive, sensors, window inside the data, parameters known (in ``defaults``, else the
    drive's reference)."""
    if drive not in gp.DRIVES:
        raise ExperimentError(f"{label}: drive must be one of {gp.DRIVES}, got {drive!r}")
    bad = [s for s in sensors if s not in SENSORS]
    if bad:
        raise ExperimentError(f"{label}: unknown sensor(s) {bad} (known: {list(SENSORS)})")
    if "length" not in sensors:
        raise ExperimentError(f"{label}: every experiment needs the length sensor")
    if "robot_length_m" not in exp:
        raise ExperimentError(f"{label}: no robot_length_m column")
    if "pressure" in sensors and "pressure_Pa" not in exp:
        raise ExperimentError(f"{label}: the pressure sensor is named but there is no pressure_Pa column")
    if window is not None:
        if len(window) != 2 or not window[0] < window[1]:
            raise ExperimentError(f"{label}: window must be [t_start, t_end] with t_start < t_end, got {list(window)}")
        inside = (exp.time >= window[0]) & (exp.time <= window[1])
        if np.count_nonzero(inside) < 2:
            raise ExperimentError(
                f"{label}: its window {window[0]:g}–{window[1]:g} s holds no data (the data span "
                f"{exp.time[0]:g}–{exp.time[-1]:g} s)"
            )
    base = defaults if defaults is not None else gp.reference(drive)
    for key in parameters:
        try:
            gp.resolve_name(base, key)
        except (KeyError, ValueError):
            raise ExperimentError(f"{label}: unknown parameter {key!r} (see `growjax params`)") from None
    return Run(name, exp, drive, robot, rig, window, tuple(sensors), dict(parameters), defaults)


def _unique_names(runs: list[Run]) -> list[Run]:
    seen: dict[str, int] = {}
    out = []
    for r in runs:
        k = seen.get(r.name, 0)
        seen[r.name] = k + 1
        out.append(r if k == 0 else dataclasses.replace(r, name=f"{r.name}-{k + 1}"))
    return out


@dataclasses.dataclass(frozen=True)
class Scope:
    """A free parameter and how many copies of it a set fits: one for all runs (``"shared"``), one per robot,
    per rig, or per run (``"experiment"``)."""

    name: str
    scope: str = "shared"

    @classmethod
    def parse(cls, text: str, base: gp.Parameters, default: str = "shared") -> Scope:
        """``NAME`` or ``NAME@SCOPE`` (e.g. ``Y@robot``); ValueError naming an unknown parameter or scope."""
        name, _, scope = text.partition("@")
        scope = scope.strip() or default
        if scope not in SCOPES:
            raise ValueError(f"--free {text}: unknown scope {scope!r} (one of {', '.join(SCOPES)})")
        try:
            qualified = gp.resolve_name(base, name.strip())
        except (KeyError, ValueError):
            raise ValueError(f"--free {text}: unknown parameter {name.strip()!r} (see `growjax params`)") from None
        return cls(qualified, scope)
