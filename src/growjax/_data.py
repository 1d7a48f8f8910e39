"""Where the data sets shipped with growjax are, located through :mod:`importlib.resources` (no path arithmetic)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

DEFAULT_DATASET = "synthetic_forward.csv"


def dataset(name: str) -> Path:
    """Path of the shipped data set ``name`` (a file in the package's ``datasets`` folder); FileNotFoundError
    naming the ones there if it is not one of them."""
    folder = resources.files("growjax") / "datasets"
    path = folder / name
    if not path.is_file():
        shipped = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
        raise FileNotFoundError(f"growjax ships no data set {name!r}; it ships {shipped}")
    return Path(str(path))


def default_data_path() -> Path:
    """The synthetic forward-drive experiment shipped with the package (the commands' default data)."""
    return dataset(DEFAULT_DATASET)
