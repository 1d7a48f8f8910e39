"""The public MAMMOBOT experiment as the benchmarks on it use it: 0–10 s, forward drive, published parameters."""

from __future__ import annotations

from pathlib import Path

import growjax as gj
from growjax.data import experiment as ex


def public_experiment(data: str | None = None):
    """(experiment on 0–10 s, published forward-drive parameters, the 0–10 s configuration, its inputs) from the
    folder ``data`` (default: ``../shared/data/mammobot`` beside the checkout); SystemExit where it is absent."""
    folder = Path(data) if data else ex.shared_experiment_dir()
    if folder is None:
        raise SystemExit("the public experiment was not found: pass --data DIR")
    exp = ex.read(Path(folder) / "experiment.csv").window(10.0 + 1e-9)
    base, config = gj.reference("forward"), gj.Config(t1=10.0)
    return exp, base, config, ex.to_inputs(exp, "forward", base, config.t0, config.t1)
