"""DATA, as every command reads it: an `growjax.data.sets.ExperimentSet`.

DATA is nothing (the synthetic experiment shipped with growjax), an experiment CSV, a folder with the rig's MATLAB
files, ``mammobot`` (a named public data set, `growjax.data.datasets.fetch`), several files (one robot on one rig)
or a TOML manifest. Each experiment takes the parameter values recorded beside its file (``X.json`` beside
``X.csv``) with ``--param`` on top. One file is read into the simulated window [t0, ``--t-end``]: a window that
runs past the data's end is shrunk to it (a one-line note), one that does not overlap them is refused. A file's
columns that are not used, and a forward drive's demand taken as the published pulse train for want of a
``pressure_demand_Pa`` column, are each said in a one-line note on stderr.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from growjax.data.sets import ExperimentSet, Run


def parse_param(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` → (name, value); ValueError with the problem named."""
    if "=" not in text:
        raise ValueError(f"--param expects NAME=VALUE, got {text!r}")
    name, value = text.split("=", 1)
    try:
        return name.strip(), float(value)
    except ValueError:
        raise ValueError(f"--param {name}: {value!r} is not a number") from None


def fixed_parameters(args) -> dict:
    """{name: value} of ``--param`` (SI units); ValueError naming an unknown parameter or a value outside its
    physical range."""
    from growjax.model import params as gp

    base = gp.reference(getattr(args, "drive", "forward"))
    fixed = {}
    for text in args.param:
        name, value = parse_param(text)
        qualified = parameter_name(base, name, "--param")
        try:
            gp.validate(gp.replace(base, **{qualified: value}))
        except ValueError as err:
            raise ValueError(f"--param {text}: {err}") from None
        fixed[name] = value
    return fixed


def parameter_name(base, name: str, option: str) -> str:
    """The qualified name of the parameter ``name`` of ``option``; ValueError naming the option, the name and the
    nearest known names."""
    import difflib

    from growjax.model import params as gp

    try:
        return gp.resolve_name(base, name)
    except ValueError as err:
        if "ambiguous" in str(err):
            raise ValueError(f"{option} {name}: {err}") from None
    names = gp.parameter_names(base)
    known = [*gp.ALIASES, *names, *(q.split(".", 1)[1] for q in names)]
    near = difflib.get_close_matches(name, known, n=3)
    hint = f"; did you mean {' or '.join(repr(n) for n in near)}?" if near else ""
    raise ValueError(f"{option} {name}: unknown parameter{hint} (names as in `growjax params`)") from None


def check_options(args) -> None:
    """Refuse, before any work, an empty scored window (``--t-start`` after ``--t-end``) and the parameter options
    that name an unknown parameter, a scope or a value out of range: ``--param``, ``--tolerance``, ``--free``,
    ``--for``, ``--hierarchical``."""
    from growjax.calibration import tolerance as tl
    from growjax.data import sets as xs
    from growjax.model import params as gp

    t_start, t_end = getattr(args, "t_start", None), getattr(args, "t_end", None)
    if t_start is not None and t_end is not None and not t_start < t_end:
        raise ValueError(f"--t-start {t_start:g} s must lie before --t-end {t_end:g} s")
    base = gp.reference(getattr(args, "drive", "forward"))
    if hasattr(args, "param"):
        fixed_parameters(args)
    tolerances = getattr(args, "tolerance", None) or []
    if [t.strip().lower() for t in tolerances] != ["none"]:
        for text in tolerances:
            name, _ = tl.parse(text)
            parameter_name(base, name, "--tolerance")
    single = not is_set(getattr(args, "data", None) or [])
    for text in getattr(args, "free", None) or []:
        if single and "@" in text:
            raise ValueError(f"--free {text}: a scope (@{'/@'.join(xs.SCOPES[1:])}) applies to several experiments")
        parameter_name(base, text.partition("@")[0].strip(), "--free")
        if not single:
            xs.Scope.parse(text, base)
    for name in getattr(args, "design_for", None) or []:
        parameter_name(base, name, "--for")
    if getattr(args, "hierarchical", None):
        parameter_name(base, args.hierarchical, "--hierarchical")


def recorded_parameters(data: Path) -> dict:
    """Parameter values recorded in a JSON file beside ``data`` (``X.json`` beside ``X.csv``), under ``"truth"`` or
    ``"parameters"`` ({name: value}, SI units); {} when there is none."""
    beside = data.with_suffix(".json") if data.suffix else None
    if beside is None or not beside.is_file():
        return {}
    try:
        record = json.loads(beside.read_text())
    except (OSError, ValueError):
        return {}
    values = record.get("truth", record.get("parameters")) if isinstance(record, dict) else None
    if not isinstance(values, dict):
        return {}
    return {k: float(v) for k, v in values.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def data_path(data: str | None, data_dir: str | None = None, default: Path | None = None) -> Path:
    """The experiment a command reads: a path, a named public data set (``mammobot``:
    `growjax.data.datasets.fetch`, from ``data_dir`` where given), or, where none is given, ``default`` (None: the
    shipped synthetic experiment)."""
    from growjax.data import datasets

    if data is not None and (Path(data).exists() or data not in datasets.NAMES):
        if data_dir is not None:
            raise ValueError(f"--data-dir applies to a named data set ({', '.join(datasets.NAMES)}), not to {data}")
        return Path(data)
    if data is None:
        if data_dir is not None:
            raise ValueError(f"--data-dir applies to a named data set: name it ({', '.join(datasets.NAMES)})")
        return datasets.default_data_path() if default is None else default
    return datasets.fetch(data, data_dir=data_dir)


def notice(args, text: str) -> None:
    """One line on stderr: ``growjax COMMAND: note: text``."""
    print(f"growjax {args.command}: note: {text}", file=sys.stderr)


def unused_columns_note(args, exp) -> None:
    """A note naming the columns of ``exp``'s file that are not used (none where every column is)."""
    if exp.unused:
        names = ", ".join(repr(c) for c in exp.unused)
        notice(args, f"{exp.source}: column{'s' * (len(exp.unused) > 1)} {names} not used (not growjax columns)")


def published_demand_note(args, exp, drive: str, named: bool) -> None:
    """A note where a user's file on the forward drive has no demand column: the published pulse train is
    simulated (``named``: a shipped or named public data set, recorded under that pulse: no note)."""
    if drive == "forward" and "pressure_demand_Pa" not in exp and not named and not _made_under_the_pulse(exp):
        notice(
            args,
            f"{exp.source} has no pressure_demand_Pa column: the demand is taken as the published 0/150 kPa "
            "pulse train",
        )


def _made_under_the_pulse(exp) -> bool:
    """Whether the file's JSON sidecar (the same name, ``.json``) records it was made under the published pulse."""
    sidecar = Path(exp.source).with_suffix(".json") if exp.source else None
    try:
        return str(json.loads(sidecar.read_text()).get("inputs", "")).startswith("published pulse")
    except (AttributeError, OSError, ValueError):
        return False


def in_window(args, exp, data: Path):
    """The samples of ``exp`` in the simulated window [t0, ``--t-end``]. A window that runs past the data's end is
    shrunk to it (``args.t_end`` set, a one-line note on stderr); ExperimentError naming both spans where the
    data and the window do not overlap."""
    import growjax as gj
    from growjax.data.experiment import ExperimentError

    t0, t1 = gj.Config().t0, args.t_end
    first, last = float(exp.time[0]), float(exp.time[-1])
    spans = f"{data} holds data over {first:g}–{last:g} s and the simulated window is {t0:g}–{t1:g} s (--t-end)"
    inside = exp.window(t1 + 1e-9)
    if first > t1 or last <= t0:
        raise ExperimentError(f"{spans}: they do not overlap")
    if inside.time.size < 2:
        raise ExperimentError(f"{spans}: only one sample lies in the window")
    if last < t1 - 1e-9:
        notice(args, f"{spans}: the window is shrunk to {t0:g}–{last:g} s")
        args.t_end = last
    return inside


def is_set(paths) -> bool:
    """Whether DATA's ``paths`` name a set: several files, or one TOML manifest."""
    return len(paths) > 1 or (len(paths) == 1 and Path(paths[0]).suffix.lower() == ".toml")


@dataclasses.dataclass(frozen=True)
class Data:
    """DATA, read.

    Attributes:
        experiments: the runs, each with its fixed values (recorded beside its file, ``--param`` on top).
        sources: where each run came from, as the summaries name them.
        origin: where the fixed values came from: ``{"recorded_beside_data": {...}, "fixed": {...}}`` for one
            file, ``{"fixed": {...}}`` for a set (SI units).
        single: whether DATA was one file (else a set: several files, or a manifest).
        growth_law: the growth law of `base`.
    """

    experiments: ExperimentSet
    sources: tuple[str, ...]
    origin: dict
    single: bool
    growth_law: str = "reference"

    @property
    def run(self) -> Run:
        """The one run of a single file (`growjax.data.sets.Run`)."""
        (run,) = self.experiments.runs
        return run

    @property
    def path(self) -> Path:
        """The single file's path."""
        return Path(self.sources[0])

    @property
    def experiment(self):
        """The single file's experiment, in the simulated window (`growjax.data.experiment.Experiment`)."""
        return self.run.experiment

    def base(self, drive: str | None = None):
        """The single file's parameters on ``drive`` (default its own): the drive's reference of `growth_law`
        with the run's fixed values, validated (`growjax.Parameters`)."""
        import growjax as gj

        run = self.run if drive is None else dataclasses.replace(self.run, drive=drive)
        params = run.base(self.growth_law)
        gj.validate(params)
        return params


def load(args, growth_law: str = "reference", as_set: bool | None = None) -> Data:
    """DATA of the parsed arguments ``args`` (``args.data``: None, a path, or a list of them), as a set where
    ``as_set`` (default: where `is_set`), else as one file on ``--drive``, its parameters of ``growth_law``."""
    paths = [] if args.data is None else [args.data] if isinstance(args.data, str) else list(args.data)
    if as_set if as_set is not None else is_set(paths):
        return _load_set(args, paths)
    return _load_one(args, paths[0] if paths else None, growth_law)


def _load_one(args, given: str | None, growth_law: str) -> Data:
    from growjax.data import datasets
    from growjax.data import experiment as ex
    from growjax.data import sets as xs

    data = data_path(given, args.data_dir)
    exp = in_window(args, ex.read(data, catheter=args.catheter), data)
    unused_columns_note(args, exp)
    published_demand_note(args, exp, args.drive, named=given is None or given in datasets.NAMES)
    recorded = recorded_parameters(data)
    fixed = fixed_parameters(args)
    run = xs.Run(data.stem or data.name, exp, drive=args.drive, parameters={**recorded, **fixed})
    loaded = Data(
        xs.ExperimentSet((run,)),
        (str(data),),
        {"recorded_beside_data": {k: v for k, v in recorded.items() if k not in fixed}, "fixed": fixed},
        True,
        growth_law,
    )
    loaded.base()  # a bad value is refused here
    return loaded


def _load_set(args, paths) -> Data:
    """The set of ``paths`` (one TOML manifest, or several files: one robot on one rig, scored from ``--t-start``
    to ``--t-end``), with the values recorded beside each file and ``--param`` fixed."""
    import growjax as gj
    from growjax.data import sets as xs

    fixed = fixed_parameters(args)
    if len(paths) > 1 and any(Path(p).suffix.lower() == ".toml" for p in paths):
        raise ValueError("a manifest (.toml) describes the whole set: give it alone")
    if len(paths) == 1:
        exps = xs.ExperimentSet.from_manifest(paths[0], catheter=args.catheter)
    else:
        window = (args.t_start if args.t_start is not None else gj.Config().t0, args.t_end)
        exps = xs.ExperimentSet.from_files(paths, drive=args.drive, window=window, catheter=args.catheter)
        exps = xs.ExperimentSet(
            tuple(
                dataclasses.replace(r, parameters={**recorded_parameters(Path(p)), **r.parameters})
                for r, p in zip(exps, paths)
            )
        )
    if fixed:
        exps = xs.ExperimentSet(tuple(dataclasses.replace(r, parameters={**r.parameters, **fixed}) for r in exps))
    for run in exps:
        unused_columns_note(args, run.experiment)
        published_demand_note(args, run.experiment, run.drive, named=False)
        gj.validate(run.base())
    return Data(exps, tuple(str(p) for p in paths), {"fixed": fixed}, False)


__all__ = [
    "Data",
    "check_options",
    "data_path",
    "fixed_parameters",
    "in_window",
    "is_set",
    "load",
    "notice",
    "parameter_name",
    "parse_param",
    "published_demand_note",
    "recorded_parameters",
    "unused_columns_note",
]
