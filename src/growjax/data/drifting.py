"""Synthetic experiments whose parameter drifts: test data for a filter that follows a slowly varying parameter.

The reference configuration (never the fast one a filter runs) is stepped from segment to segment, the parameter
held over each at its value at the segment's middle; noise is added to the measured columns as
``growjax.data.synthetic.make_experiment`` adds it.
"""

from __future__ import annotations

import numpy as np

import growjax as gj
from growjax.data import experiment as ex
from growjax.data import synthetic as sy
from growjax.model import effects as fx
from growjax.model import params as gp
from growjax.simulation import reference
from growjax.simulation.simulate import input_breaks, simulate_from


def drifting_experiment(
    parameter: str,
    change: float,
    *,
    seed: int,
    t_end: float = 10.0,
    segment: float = 0.25,
    base=None,
    inputs="synthetic",
    noise: dict | None = None,
    dt: float = 0.01,
    rtol: float = 1e-6,
) -> sy.SyntheticExperiment:
    """A synthetic experiment whose ``parameter`` drifts: ψ(t) = ψ₀ (1 + ``change`` · t/``t_end``), held over each
    ``segment`` s (a staircase; the value at the segment's middle), simulated by the reference configuration from
    segment to segment (``growjax.simulation.simulate.simulate_from``), forward drive.

    Args:
        parameter: its name (``Y``, ``robot.yield_pressure``, ...).
        change: its relative change over the record (0.1: +10 %).
        seed: seed of the noise, drawn per column in the order of ``noise``.
        t_end, dt, inputs, base, rtol: as ``growjax.data.synthetic.make_experiment``.
        segment: how long each value is held, s.
        noise: {column: sd} of the noisy columns (default: 0.2 mm on the length, 500 Pa on the pressure, 5 µm on
            the syringe displacement).

    Returns:
        ``growjax.data.synthetic.SyntheticExperiment``, its ``metadata`` holding the drift (``parameter``,
        ``values`` (T,) at the samples) and the noise-free length (``noise_free_length_m``).

    Raises:
        RuntimeError: the reference solver failed in a segment.
    """
    base = gj.reference("forward") if base is None else base
    name = gp.resolve_name(base, parameter)
    noise = noise or {
        "robot_length_m": sy.NOISE_LENGTH_M,
        "pressure_Pa": sy.NOISE_PRESSURE_PA,
        "syringe_displacement_m": 5e-6,
    }
    model_inputs, time, cols, description = sy.resolve_inputs(inputs, "forward", base, t_end, dt)
    config = gj.Config(fidelity="reference", t1=float(time[-1]), rtol=rtol, atol=rtol, stop_at_pressure_limit=False)
    breaks = input_breaks(model_inputs, config)
    nominal = float(gj.get(base, name))
    edges = np.unique(np.concatenate([np.arange(config.t0, time[-1], segment), [time[-1]]]))
    state = reference.initial_state(fx.apply_all(base), config)
    out = {k: np.full(time.size, np.nan) for k in ("length", "pressure", "syringe_displacement", "robot_flow")}
    values = np.full(time.size, np.nan)
    for ta, tb in zip(edges[:-1], edges[1:]):
        value = nominal * (1.0 + change * 0.5 * (ta + tb) / t_end)
        rows = np.flatnonzero((time > ta) & (time <= tb))
        ts = np.concatenate([time[rows], [tb]]) if rows.size == 0 or time[rows[-1]] < tb else time[rows]
        traj = simulate_from(gj.replace(base, **{name: value}), model_inputs, config, state, (ta, tb), ts, breaks)
        if int(traj.status) == gj.SOLVER_FAILED:
            raise RuntimeError(f"the reference solve failed between {ta:.3f} s and {tb:.3f} s")
        state = traj.final_state
        for k in out:
            out[k][rows] = np.asarray(getattr(traj, k))[: rows.size]
        values[rows] = value
    series = {**sy.noisy(out, noise, np.random.default_rng(seed)), **cols}
    ex.validate_series(time, series, "synthetic experiment")
    meta = {
        "effect": None,
        "drift": {"parameter": name, "change": change, "segment_s": segment, "values": values.tolist()},
        "noise_free_length_m": out["length"].tolist(),
        "noise_sd": noise,
        "seed": int(seed),
        "drive": "forward",
        "t_end_s": float(time[-1]),
        "inputs": description,
        "base_parameters": sy.base_overrides(base, "forward"),
        "solver": {"fidelity": "reference", "rtol": rtol, "atol": rtol},
        "generator": "growjax.data.drifting.drifting_experiment",
    }
    return sy.SyntheticExperiment(time, series, f"synthetic: {name} drifting by {change:+.0%}, seed {seed}", meta)


__all__ = ["drifting_experiment"]
