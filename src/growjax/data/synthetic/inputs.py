"""The inputs of a synthetic experiment: the public experiment's, the shipped ones', or given `growjax.Inputs`."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax.data import experiment as ex

__all__ = ["SHIPPED_INPUTS", "resolve_inputs", "shipped_inputs_path"]

SHIPPED_INPUTS = "synthetic_forward.csv"


def shipped_inputs_path() -> Path | None:
    """The shipped ``synthetic_forward.csv`` (package data ``growjax/data/datasets``)."""
    from importlib import resources

    cand = Path(str(resources.files("growjax.data") / "datasets" / SHIPPED_INPUTS))
    return cand if cand.exists() else None


def _source_experiment(kind: str, t_end: float, dt: float) -> tuple[ex.Experiment, str]:
    """(experiment whose input columns are used, description) for ``inputs="public"|"synthetic"``."""
    if kind == "public":
        folder = ex.shared_experiment_dir()
        if folder is not None:
            exp = ex.read(folder / "experiment.csv")
            return exp, (
                "public MAMMOBOT experiment (../shared/data/mammobot/experiment.csv): its catheter_length_m, "
                "published pulse 0/150 kPa (period 1.3 s, width 90 %, delay 0.26 s)"
            )
    elif kind != "synthetic":
        raise ValueError(f"inputs must be 'public', 'synthetic' or a growjax.Inputs, got {kind!r}")
    prefix = "" if kind == "synthetic" else "fallback (public experiment absent): "
    path = shipped_inputs_path()
    if path is not None:
        exp = ex.read(path)
        return exp, (
            f"{prefix}shipped {SHIPPED_INPUTS}: catheter_length_m 0.004 + 0.004 t m, published pulse "
            "0/150 kPa (period 1.3 s, width 90 %, delay 0.26 s)"
        )
    time = _grid(t_end, dt)
    return ex.Experiment(time, {"catheter_length_m": 0.004 + 0.004 * time}, "generated"), (
        f"{prefix}{SHIPPED_INPUTS} absent: catheter 0.004 + 0.004 t m, published pulse 0/150 kPa"
    )


def _grid(t_end: float, dt: float) -> np.ndarray:
    n = round(t_end / dt)
    return np.round(np.arange(1, n + 1) * dt, 10)


def _thin(time: np.ndarray, t_end: float, dt: float) -> np.ndarray:
    """Indices of the samples of ``time`` on the grid dt, 2dt, … ≤ t_end."""
    keep = time <= t_end + 1e-9
    k = np.round(time / dt)
    keep &= np.abs(time - k * dt) < 1e-6 * dt + 1e-12
    return np.flatnonzero(keep)


def _is_published(signal) -> bool:
    pub = gj.published_pulse()
    if not isinstance(signal, gj.PulseTrain):
        return False
    return all(float(getattr(signal, f)) == float(getattr(pub, f)) for f in ("amplitude", "period", "width", "delay"))


def resolve_inputs(inputs, drive: str, base, t_end: float, dt: float = 0.01):
    """(Inputs, sample times (T,), input columns {name: (T,)}, description) for ``inputs`` (see module docstring).

    The sample times are those of the source experiment on the grid ``dt`` up to ``t_end`` (s), or
    dt, 2dt, …, t_end for given Inputs. ValueError if the source ends before ``t_end``.
    """
    if isinstance(inputs, gj.Inputs):
        time = _grid(t_end, dt)
        t = jnp.asarray(time)
        cols = {"catheter_length_m": np.asarray(jax.vmap(inputs.catheter_length)(t))}
        if drive == "forward" and not _is_published(inputs.pressure_demand):
            cols["pressure_demand_Pa"] = np.asarray(jax.vmap(inputs.pressure_demand)(t))
        if drive == "inverse" and inputs.desired_length is not None:
            cols["desired_length_m"] = np.asarray(jax.vmap(inputs.desired_length)(t))
        return inputs, time, cols, "user-supplied growjax.Inputs"
    exp, description = _source_experiment(inputs, t_end, dt)
    if exp.time[-1] < t_end - 1e-9:
        raise ValueError(f"the inputs ({description}) end at {exp.time[-1]:g} s, before t_end = {t_end:g} s")
    rows = _thin(exp.time, t_end, dt)
    time = exp.time[rows]
    cols = {"catheter_length_m": np.asarray(exp["catheter_length_m"])[rows]} if "catheter_length_m" in exp else {}
    if drive == "forward":
        if "pressure_demand_Pa" in exp:
            cols["pressure_demand_Pa"] = np.asarray(exp["pressure_demand_Pa"])[rows]
        source = ex.Experiment(time, cols, exp.source)
    else:
        desired = exp["desired_length_m"] if "desired_length_m" in exp else exp["robot_length_m"]
        cols["desired_length_m"] = np.asarray(desired)[rows]
        description += "; inverse drive: its measured length as the desired length"
        source = ex.Experiment(time, cols, exp.source)
    return ex.to_inputs(source, drive, base, t1=float(time[-1])), time, cols, description
