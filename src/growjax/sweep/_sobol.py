"""Sobol indices of a sweep's scores: SALib's Saltelli design evaluated as one sweep."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from growjax.model import params as gp
from growjax.model.signals import Inputs
from growjax.simulation.config import Config
from growjax.sweep._box import Dimension
from growjax.sweep._evaluate import FAST, Measured, evaluate

__all__ = ["sobol_indices"]


def sobol_indices(
    dims: Sequence[Dimension],
    base: gp.Parameters,
    inputs: Inputs,
    config: Config = FAST,
    *,
    n_base: int = 256,
    seed: int = 0,
    n_bootstrap: int = 1000,
    measured: Measured | None = None,
    **options: Any,
) -> dict:
    """First- and total-order Sobol indices of the final length and of the length RMSE (SALib, Saltelli design).

    Args:
        dims: the box, d dimensions.
        base: the parameters the points replace fields of.
        inputs: the inputs of every run.
        config: the configuration of every run.
        n_base: base points, a power of 2: n_base·(d + 2) model runs, evaluated as one sweep.
        seed: the design's and the bootstrap's seed.
        n_bootstrap: bootstrap resamples of the confidence intervals.
        measured: (sample times s, length m): adds the indices of the length RMSE; None: the final length's only.
        **options: the other options of `evaluate` (``window``, ``chunk_size``, ``progress`` …).

    Returns:
        ``{"names": the d names, "indices": {output: {"S1", "S1_conf", "ST", "ST_conf"}}, "n_runs", "sweep"}``:
        the indices as lists ordered as ``dims``, their 95 % bootstrap half-widths, and the sweep's
        `SweepResult`. An output with failed members has ``{"error": ...}`` in place of its indices.
    """
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    dims = tuple(dims)
    problem = {"num_vars": len(dims), "names": [d.name for d in dims], "bounds": [[0.0, 1.0]] * len(dims)}
    unit = sobol_sample.sample(problem, n_base, calc_second_order=False, seed=seed)
    values = np.column_stack([d.from_unit(unit[:, i]) for i, d in enumerate(dims)])
    result = evaluate(values, [d.name for d in dims], base, inputs, config, measured=measured, **options)
    outputs = {"final_length_m": result.final_length}
    if measured is not None:
        outputs["rmse_length_m"] = result.rmse
    indices = {}
    for key, y in outputs.items():
        if not np.all(np.isfinite(y)):
            indices[key] = {"error": f"{int(np.sum(~np.isfinite(y)))} failed members; indices not defined"}
            continue
        s = sobol_analyze.analyze(problem, y, calc_second_order=False, num_resamples=n_bootstrap, seed=seed)
        indices[key] = {k: [float(v) for v in s[k]] for k in ("S1", "S1_conf", "ST", "ST_conf")}
    return {"names": [d.name for d in dims], "indices": indices, "n_runs": int(values.shape[0]), "sweep": result}
