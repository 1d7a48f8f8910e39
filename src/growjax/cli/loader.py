"""DATA, as every command reads it: an `growjax.data.sets.ExperimentSet`.

DATA is nothing (the synthetic experiment shipped with growjax), an experiment CSV, a folder with the rig's MATLAB
files, ``mammobot`` (a named public data set, `growjax.data.datasets.fetch`), several files (one robot on one rig)
or a TOML manifest. Each experiment takes the parameter values recorded beside its file (``X.json`` beside
``X.csv``) with ``--param`` on top. One file is read into the simulated window [t0, ``--t-end``]: a window that
runs past the data's end is shrunk to it (a one-line note), one that does not overlap them is refused.
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
    """{name: value} of ``--param`` (SI units)."""
    return dict(parse_param(p) for p in args.param)


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


def data_path(data: str | None, data_dir: str | None = None) -> Path:
    """The experiment a command reads: a path, a named public data set (``mammobot``:
    `growjax.data.datasets.fetch`, from ``data_dir`` where given), or the shipped synthetic experiment."""
    from growjax.data import datasets

    if data is not None and (Path(data).exists() or data not in datasets.NAMES):
        if data_dir is not None:
            raise ValueError(f"--data-dir applies to a named data set ({', '.join(datasets.NAMES)}), not to {data}")
        return Path(data)
    if data is None:
        if data_dir is not None:
            raise ValueError(f"--data-dir applies to a named data set: name it ({', '.join(datasets.NAMES)})")
        return datasets.default_data_path()
    return datasets.fetch(data, data_dir=data_dir)


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
        print(f"growjax {args.command}: note: {spans}: the window is shrunk to {t0:g}–{last:g} s", file=sys.stderr)
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
    from growjax.data import experiment as ex
    from growjax.data import sets as xs

    data = data_path(given, args.data_dir)
    exp = in_window(args, ex.read(data, catheter=args.catheter), data)
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
        gj.validate(run.base())
    return Data(exps, tuple(str(p) for p in paths), {"fixed": fixed}, False)


__all__ = [
    "Data",
    "data_path",
    "fixed_parameters",
    "in_window",
    "is_set",
    "load",
    "parse_param",
    "recorded_parameters",
]
