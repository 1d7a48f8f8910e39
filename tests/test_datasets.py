"""growjax.data.datasets.fetch: the public experiment from a hash-checked local copy, and one clear line offline."""

import shutil

import numpy as np
import pytest
from conftest import REPO

from growjax import cli
from growjax.cli import loader
from growjax.data import datasets
from growjax.data import experiment as ex

SHARED = REPO.parent / "shared" / "data" / "mammobot"  # the authors' files beside the checkout
UNREACHABLE = "http://127.0.0.1:9/growjax-test/"  # the discard port: refused at once, no network needed


@pytest.fixture
def local_copy():
    if not all((SHARED / f).is_file() for f in datasets.REPOSITORIES["mammobot"]["files"]):
        pytest.skip(f"no local copy of the public MAMMOBOT experiment at {SHARED}")
    return SHARED


@pytest.fixture
def offline(monkeypatch, tmp_path):
    """The repository's URL unreachable, no local copy named, the cache in ``tmp_path``."""
    monkeypatch.setitem(datasets.REPOSITORIES["mammobot"], "base_url", UNREACHABLE)
    monkeypatch.delenv(datasets.DATA_DIR_ENV, raising=False)
    monkeypatch.setenv(datasets.CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache" / "mammobot" / "growjax-test"


def test_fetch_checks_and_converts_a_local_copy_to_the_experiment_csv(local_copy, tmp_path, monkeypatch):
    path = datasets.fetch("mammobot", data_dir=local_copy, cache_dir=tmp_path)
    assert path.is_relative_to(tmp_path) and path.name == "experiment.csv"
    exp = ex.read(path)
    mat = ex.read(local_copy)  # the MATLAB files, decoded directly
    assert exp.time.size == 2499 and exp.time[0] == pytest.approx(0.01) and exp.time[-1] == pytest.approx(24.99)
    for column in ("robot_length_m", "catheter_length_m"):
        np.testing.assert_array_equal(exp[column], mat[column])
    if (local_copy / "experiment.csv").is_file():  # the CSV published beside them (10 significant digits)
        np.testing.assert_allclose(
            exp["robot_length_m"], ex.read(local_copy / "experiment.csv")["robot_length_m"], rtol=0, atol=1e-11
        )
    monkeypatch.setenv(datasets.DATA_DIR_ENV, str(local_copy))  # the environment names the copy instead
    assert datasets.fetch("mammobot", cache_dir=tmp_path) == path


def test_a_local_copy_with_a_changed_or_missing_file_is_refused(tmp_path):
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "kings_ts.mat").write_bytes(b"not the authors' file")
    with pytest.raises(datasets.DatasetError, match=r"kings_ts.mat has SHA-256 [0-9a-f]{64}, not the published"):
        datasets.fetch("mammobot", data_dir=copy, cache_dir=tmp_path / "cache")
    (copy / "kings_ts.mat").unlink()
    with pytest.raises(datasets.DatasetError, match="no file kings_ts.mat in"):
        datasets.fetch("mammobot", data_dir=copy, cache_dir=tmp_path / "cache")
    with pytest.raises(ValueError, match="unknown data set 'bogus'; choose from mammobot"):
        datasets.fetch("bogus")


def test_offline_fetch_fails_with_one_line_naming_the_url_and_the_cache_folder(offline):
    with pytest.raises(datasets.DatasetError) as err:
        datasets.fetch("mammobot")
    message = str(err.value)
    assert "\n" not in message
    assert f"could not download {UNREACHABLE}kings_ts.mat into the cache folder {offline} " in message
    assert "--data-dir" in message and datasets.DATA_DIR_ENV in message


def test_the_command_line_fails_in_one_line_offline_and_on_a_bad_copy(offline, tmp_path, capsys):
    assert cli.main(["simulate", "mammobot", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"{UNREACHABLE}kings_ts.mat" in err and str(offline) in err
    assert cli.main(["simulate", "mammobot", "--data-dir", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.strip() == (
        f"growjax simulate: error: no file kings_ts.mat in {tmp_path} (the data set's files: a copy of the authors')"
    )


def test_the_command_line_names_the_data_set_with_a_local_copy(offline, local_copy):
    path = loader.data_path("mammobot", str(local_copy))
    assert path == offline / "experiment.csv" and ex.read(path).time.size == 2499
    with pytest.raises(ValueError, match="--data-dir applies to a named data set"):
        loader.data_path(str(local_copy / "kings_ts.mat"), str(local_copy))
    with pytest.raises(ValueError, match="--data-dir applies to a named data set: name it"):
        loader.data_path(None, str(local_copy))


def test_a_folder_named_like_a_data_set_is_read_as_a_folder(tmp_path, monkeypatch, local_copy):
    folder = tmp_path / "mammobot"
    shutil.copytree(local_copy, folder)
    monkeypatch.chdir(tmp_path)
    assert loader.data_path("mammobot") == folder.relative_to(tmp_path)
