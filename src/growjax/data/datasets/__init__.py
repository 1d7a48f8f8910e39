"""Public data sets: downloaded from their authors at a pinned commit, hash-checked, cached, converted.

``fetch("mammobot")`` gives the public MAMMOBOT experiment (the measured robot length and the catheter length of
the King's College London rig, 2499 samples at 100 Hz, 0.01–24.99 s) as a growjax experiment CSV::

    from growjax.data import datasets
    from growjax.data import experiment as ex
    exp = ex.read(datasets.fetch("mammobot"))

The files come from the authors' repository (:data:`REPOSITORIES`) at the commit named there, each checked
against its SHA-256 before use, and are kept in a cache folder (``cache_dir``; default: the user cache,
``~/.cache/growjax/data`` on Linux, or ``$GROWJAX_DATA_CACHE``). Offline, point ``data_dir`` (or
``$GROWJAX_DATA_DIR``; the command line's ``--data-dir``) at a folder holding a copy of the files: they are
checked against the same hashes, and only the converted CSV is written, to the cache folder.

This folder also holds the data sets shipped inside the package (``synthetic_forward.csv`` and the discovery
references), read through :mod:`importlib.resources`.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from importlib import resources
from pathlib import Path

DATA_DIR_ENV = "GROWJAX_DATA_DIR"  # a folder holding a local copy of a data set's files
CACHE_ENV = "GROWJAX_DATA_CACHE"  # where downloads and converted files go

REPOSITORIES = {
    "mammobot": {
        "base_url": "https://raw.githubusercontent.com/IGeorgilas/MAMMOBOT_UoB_Public/"
        "623d2fc716545511efbaa891d836307580b9dff5/",
        "files": {  # name: SHA-256
            "kings_ts.mat": "12ad6337e59295f5db1f8401f470f032526f403abb5c1200be795de4692daaca",
            "lin_c_ts.mat": "d82603c8e40a5eb04bf46b0aba771440f4c33d543f761fbca78cac32ac13e147",
        },
        "licence": "GPL-3.0",
    },
}
NAMES = tuple(REPOSITORIES)


class DatasetError(OSError):
    """A data set that cannot be had: no download, a missing file or a file whose hash differs."""


def cache_folder(cache_dir=None) -> Path:
    """The folder downloads and converted files go to: ``cache_dir``, else ``$GROWJAX_DATA_CACHE``, else the
    user cache's ``growjax/data``."""
    if cache_dir is not None:
        return Path(cache_dir)
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    import pooch

    return Path(pooch.os_cache("growjax")) / "data"


def fetch(name: str = "mammobot", data_dir=None, cache_dir=None) -> Path:
    """Path of the growjax experiment CSV (``time_s``, ``robot_length_m``, ``catheter_length_m``) of the public
    data set ``name`` (:data:`NAMES`).

    ``data_dir`` (default ``$GROWJAX_DATA_DIR``): a folder with a copy of the data set's files, used instead of
    downloading; ``cache_dir``: see :func:`cache_folder`. Raises :class:`DatasetError` (one line naming the URL
    and the cache folder) when the files cannot be downloaded, and when a file is missing or its SHA-256 differs.
    """
    if name not in REPOSITORIES:
        raise ValueError(f"unknown data set {name!r}; choose from {', '.join(NAMES)}")
    repo = REPOSITORIES[name]
    folder = cache_folder(cache_dir) / name / _commit(repo)
    data_dir = data_dir if data_dir is not None else os.environ.get(DATA_DIR_ENV) or None
    if data_dir is not None:
        paths = {f: _checked(Path(data_dir) / f, digest) for f, digest in repo["files"].items()}
    else:
        paths = {f: _download(repo["base_url"] + f, digest, folder) for f, digest in repo["files"].items()}
    return _converted(paths, folder / "experiment.csv")


def _commit(repo: dict) -> str:
    return repo["base_url"].rstrip("/").rsplit("/", 1)[-1][:12]


def _checked(path: Path, digest: str) -> Path:
    """``path`` if it exists and its SHA-256 is ``digest``; else DatasetError."""
    if not path.is_file():
        raise DatasetError(f"no file {path.name} in {path.parent} (the data set's files: a copy of the authors')")
    actual = hashlib.sha256(path.read_bytes()).hexdigest()
    if actual != digest:
        raise DatasetError(f"{path} has SHA-256 {actual}, not the published file's {digest}")
    return path


def _download(url: str, digest: str, folder: Path) -> Path:
    """The file at ``url`` in ``folder`` (downloaded once by pooch, hash-checked); DatasetError naming the URL and
    the folder when it cannot be had."""
    import pooch

    try:
        return Path(
            pooch.retrieve(
                url, known_hash=f"sha256:{digest}", fname=url.rsplit("/", 1)[-1], path=folder, progressbar=False
            )
        )
    except ValueError as err:  # pooch: the download's hash differs
        raise DatasetError(
            f"{url}: the downloaded file differs from the published one ({' '.join(str(err).split())[:200]})"
        ) from None
    except Exception as err:  # noqa: BLE001  (requests' connection and HTTP errors, the cache folder's OSError)
        status = getattr(getattr(err, "response", None), "status_code", None)
        reason = type(err).__name__ + (f" {status}" if status else "")
        raise DatasetError(
            f"could not download {url} into the cache folder {folder} ({reason}); offline, pass "
            f"data_dir= (command line: --data-dir, or set {DATA_DIR_ENV}) to a folder holding a copy "
            f"of the data set's files"
        ) from None


def _converted(paths: dict, csv: Path) -> Path:
    """The experiment CSV ``csv`` converted from the MATLAB timeseries (written once, atomically)."""
    from growjax.data import experiment as ex

    if csv.is_file():
        return csv
    exp = ex.read_mat_experiment(paths["kings_ts.mat"], paths["lin_c_ts.mat"])
    csv.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=csv.parent) as tmp:
        part = Path(tmp) / csv.name
        ex.write_csv(part, exp.time, exp.series)
        os.replace(part, csv)
    return csv


__all__ = ["CACHE_ENV", "DATA_DIR_ENV", "NAMES", "REPOSITORIES", "DatasetError", "cache_folder", "fetch"]


DEFAULT_DATASET = "synthetic_forward.csv"  # the commands' default data


def dataset(name: str) -> Path:
    """Path of the shipped data set ``name`` (a file in the package's ``datasets`` folder); FileNotFoundError
    naming the ones there if it is not one of them."""
    folder = resources.files("growjax.data") / "datasets"
    path = folder / name
    if not path.is_file():
        shipped = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
        raise FileNotFoundError(f"growjax ships no data set {name!r}; it ships {shipped}")
    return Path(str(path))


def default_data_path() -> Path:
    """The synthetic forward-drive experiment shipped with the package (the commands' default data)."""
    return dataset(DEFAULT_DATASET)
