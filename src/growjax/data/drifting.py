"""Synthetic experiments whose parameters change during the record: a slow drift (test data for a filter that
follows a slowly varying parameter) or a sudden switch (an effect appearing: a leak opening, a tip load; test
data for a change detector).

The reference configuration (never the fast one a filter runs) is stepped from segment to segment, the parameters
held over each; noise is added to the measured columns as ``growjax.data.synthetic.make_experiment`` adds it.
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

DEFAULT_NOISE = {
    "robot_length_m": sy.NOISE_LENGTH_M,
    "pressure_Pa": sy.NOISE_PRESSURE_PA,
    "syringe_displacement_m": 5e-6,
}


def stepped(base, model_inputs, time, edges, held, rtol: float) -> tuple[dict, dict]:
    """The reference configuration stepped over the segments between ``edges`` (s), forward drive, the parameters
    ``held(ta, tb)`` ({name: value}) set on ``base`` over each segment [ta, tb].

    Returns:
        ({output: (T,) at ``time``} of the length, pressure, syringe displacement and inlet flow, {name: (T,) the
        value held at each sample}).

    Raises:
        RuntimeError: the reference solver failed in a segment.
    """
    config = gj.Config(fidelity="reference", t1=float(time[-1]), rtol=rtol, atol=rtol, stop_at_pressure_limit=False)
    breaks = input_breaks(model_inputs, config)
    state = reference.initial_state(fx.apply_all(base), config)
    out = {k: np.full(time.size, np.nan) for k in ("length", "pressure", "syringe_displacement", "robot_flow")}
    values: dict = {}
    for ta, tb in zip(edges[:-1], edges[1:]):
        now = held(ta, tb)
        rows = np.flatnonzero((time > ta) & (time <= tb))
        ts = np.concatenate([time[rows], [tb]]) if rows.size == 0 or time[rows[-1]] < tb else time[rows]
        traj = simulate_from(gj.replace(base, **now), model_inputs, config, state, (ta, tb), ts, breaks)
        if int(traj.status) == gj.SOLVER_FAILED:
            raise RuntimeError(f"the reference solve failed between {ta:.3f} s and {tb:.3f} s")
        state = traj.final_state
        for k in out:
            out[k][rows] = np.asarray(getattr(traj, k))[: rows.size]
        for k, v in now.items():
            values.setdefault(k, np.full(time.size, np.nan))[rows] = v
    return out, values


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
    noise = noise or DEFAULT_NOISE
    name = gp.resolve_name(base, parameter)
    nominal = float(gj.get(base, name))
    model_inputs, time, cols, description = sy.resolve_inputs(inputs, "forward", base, t_end, dt)
    edges = np.unique(np.concatenate([np.arange(gj.Config().t0, time[-1], segment), [time[-1]]]))

    def held(ta, tb):
        return {name: nominal * (1.0 + change * 0.5 * (ta + tb) / t_end)}

    out, values = stepped(base, model_inputs, time, edges, held, rtol)
    values = values[name]
    drift = {"parameter": name, "change": change, "segment_s": segment, "values": values.tolist()}
    series, meta = _made(time, out, cols, noise, seed, description, base, rtol, drift=drift)
    meta["generator"] = "growjax.data.drifting.drifting_experiment"
    return sy.SyntheticExperiment(
        time, series, f"synthetic: {name} drifting by {change:+.0%}, seed {seed}", metadata=meta
    )


def switching_experiment(
    values: dict,
    at: float,
    *,
    seed: int,
    t_end: float = 10.0,
    base=None,
    inputs="synthetic",
    noise: dict | None = None,
    dt: float = 0.01,
    rtol: float = 1e-6,
) -> sy.SyntheticExperiment:
    """A synthetic experiment in which parameters switch suddenly: ``base`` up to ``at`` s, then ``base`` with
    ``values`` ({name: value}, e.g. a leak opening: ``{"fluid_leak.conductance": 3e-13}``), simulated by the
    reference configuration, forward drive. An effect switched on must be in ``base`` (at 0: absent).

    Args:
        values: {parameter name: its value from ``at`` on}.
        at: when they switch, s (inside the record).
        seed, t_end, base, inputs, noise, dt, rtol: as `drifting_experiment`.

    Returns:
        ``growjax.data.synthetic.SyntheticExperiment``, its ``metadata`` holding the switch (``"switch"``: the
        values and ``at_s``) and the noise-free length (``noise_free_length_m``).

    Raises:
        ValueError: ``at`` outside the record, an unknown parameter.
        RuntimeError: the reference solver failed.
    """
    base = gj.reference("forward") if base is None else base
    noise = noise or DEFAULT_NOISE
    values = {gp.resolve_name(base, k): float(v) for k, v in values.items()}
    model_inputs, time, cols, description = sy.resolve_inputs(inputs, "forward", base, t_end, dt)
    t0 = gj.Config().t0
    if not (t0 < at < time[-1]):
        raise ValueError(f"the switch time must lie inside the record ({t0}, {time[-1]}) s, got {at}")
    before = {k: float(gj.get(base, k)) for k in values}
    out, _ = stepped(
        base, model_inputs, time, np.array([t0, at, time[-1]]), lambda ta, tb: before if ta < at else values, rtol
    )
    series, meta = _made(
        time, out, cols, noise, seed, description, base, rtol, switch={"values": values, "at_s": float(at)}
    )
    meta["generator"] = "growjax.data.drifting.switching_experiment"
    return sy.SyntheticExperiment(time, series, f"synthetic: {values} from {at:.2f} s, seed {seed}", metadata=meta)


__all__ = ["DEFAULT_NOISE", "drifting_experiment", "stepped", "switching_experiment"]


def _made(time, out: dict, cols: dict, noise: dict, seed: int, description: str, base, rtol: float, **change):
    """(the measured columns with seeded noise and the input columns, checked; the sidecar's metadata, the
    ``change`` (drift or switch) under its own key) of a record made by `stepped`."""
    series = {**sy.noisy(out, noise, np.random.default_rng(seed)), **cols}
    ex.validate_series(time, series, "synthetic experiment")
    meta = {
        "effect": None,
        **change,
        "noise_free_length_m": out["length"].tolist(),
        "noise_sd": noise,
        "seed": int(seed),
        "drive": "forward",
        "t_end_s": float(time[-1]),
        "inputs": description,
        "base_parameters": sy.base_overrides(base, "forward"),
        "solver": {"fidelity": "reference", "rtol": rtol, "atol": rtol},
    }
    return series, meta
