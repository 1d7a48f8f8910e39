"""Tuning of the length controllers on the model: the PID's gains by descent on the closed-loop cost (optionally
averaged over parameter draws: robust design), the step controller by search, and a step schedule planned with
it. SI units."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

import growjax as gj
from growjax.control.controllers import (
    LengthPID,
    StepController,
    pid_loop,
    run_closed_loop,
)
from growjax.control.plant import Plant, catheter_signal
from growjax.control.targets import Target
from growjax.model.limits import Limits, limits

__all__ = [
    "DEFAULT_LOG_GAINS",
    "TuneResult",
    "parameter_draws",
    "pid_cost_fn",
    "plan_steps",
    "tune_pid",
    "tune_stepper",
]

DEFAULT_LOG_GAINS = (7.0, 7.0, 4.5)  # Kp 1e7 Pa/m (10 kPa per mm), Ki 1e7 Pa/(m s), Kd 3e4 Pa s/m


def parameter_draws(
    n: int,
    seed: int = 0,
    posterior: str | None = None,
    base: gj.Parameters | None = None,
    rel_sd: float = 0.05,
    names: Sequence[str] | None = None,
) -> dict[str, Float[np.ndarray, " n"]]:
    """Parameter sets as {name: (n,) array}, SI.

    From an ArviZ posterior file (netCDF, read as an xarray DataTree): joint draws (picked at random, seeded) of
    its posterior's variables that name a model parameter (``names`` restricts them; noise scales such as σ and
    derived sites are skipped), so the draws keep the posterior's correlations. With no file: Gaussian around the
    point estimate of ``base`` with relative s.d. ``rel_sd`` (seeded; a stand-in when no posterior is at hand),
    ``names`` default ("Y",).

    Raises:
        ValueError: for a posterior file with none of the parameters.
    """
    rng = np.random.default_rng(seed)
    base = base if base is not None else gj.reference("forward")
    if posterior:
        import xarray as xr

        with xr.open_datatree(posterior) as tree:  # ArviZ 1.x's from_netcdf
            post = tree["posterior"].to_dataset().load()
        wanted = list(names) if names is not None else [k for k in post.data_vars if _is_parameter(base, k)]
        flat = {k: np.asarray(post[k]).ravel() for k in wanted if k in post}
        if not flat:
            raise ValueError(f"{posterior} has none of the model parameters {wanted or list(post.data_vars)}")
        size = next(iter(flat.values())).size
        idx = rng.choice(size, size=n, replace=n > size)
        return {k: v[idx] for k, v in flat.items()}
    return {k: float(gj.get(base, k)) * (1.0 + rel_sd * rng.standard_normal(n)) for k in (names or ("Y",))}


def _is_parameter(base, name: str) -> bool:
    try:
        gj.get(base, name)
    except ValueError:
        return False
    return True


def _batched_params(base, draws: dict):
    """One Parameters pytree with the drawn leaves batched (leading axis n)."""
    return gj.replace(base, **{k: jnp.asarray(v) for k, v in draws.items()})


class TuneResult(NamedTuple):
    """The tuned gains.

    Attributes:
        log_gains: (3,) log10(Kp, Ki, Kd), SI.
        gains: {"Kp_Pa_per_m", "Ki_Pa_per_m_s", "Kd_Pa_s_per_m"}: the gains, SI.
        cost_history: the cost at the start and after each iteration.
        wall_s: the tuning's wall time, s.
    """

    log_gains: np.ndarray
    gains: dict
    cost_history: list
    wall_s: float


def pid_cost_fn(
    base: gj.Parameters,
    target: Target,
    t1: float,
    pid: LengthPID,
    draws: dict | None = None,
    lim: Limits | None = None,
    config: gj.Config | None = None,
) -> Callable[[Float[Array, " 3"]], Float[Array, ""]]:
    """J(log_gains) = mean over parameter draws of the squared length RMSE (mm²) of the PID closed loop on the
    fast configuration (+ a penalty on pressure above the membrane limit); jitted, vmapped over draws."""
    lim = lim or limits(base)
    config = config or gj.Config(t1=t1)
    cath = catheter_signal(target)

    def one(params, log_gains):
        plant = Plant.make(params, config)
        ctrl = eqx.tree_at(lambda c: c.log_gains, pid, log_gains)
        ts, length, pressure, _, _ = pid_loop(
            plant, ctrl, jnp.asarray(target.time), jnp.asarray(target.length), cath, lim, t1
        )
        err = (length - jnp.interp(ts, jnp.asarray(target.time), jnp.asarray(target.length))) / 1e-3
        over = jax.nn.relu(pressure - lim.membrane_limit) / 1e3
        return jnp.mean(jnp.nan_to_num(err, nan=1e2) ** 2) + jnp.mean(over**2)

    if draws:
        batched = _batched_params(base, draws)
        axes = _draw_axes(base, draws)
        fn = lambda lg: jnp.mean(jax.vmap(one, in_axes=(axes, None))(batched, lg))
    else:
        fn = lambda lg: one(base, lg)
    return jax.jit(fn)


def _draw_axes(base, draws):
    """in_axes of a parameter pytree whose drawn leaves carry a leading batch axis."""
    return gj.replace(jax.tree_util.tree_map(lambda _: None, base), **{k: 0 for k in draws})


def tune_pid(
    cost: Callable[[Float[Array, " 3"]], Float[Array, ""]],
    log_gains: Float[ArrayLike, " 3"],
    *,
    iterations: int = 10,
    step: float = 0.3,
    fd: float = 0.02,
) -> TuneResult:
    """Gradient descent on ``cost(log_gains)`` with backtracking; the gradient by central differences in
    log-gain space (``fd`` decades, a smoothed slope: at tuned high gains the closed loop's tangent grows along a
    10 s run and the cost is rough on small scales, so exact forward-mode derivatives diverge there; see
    benchmarks/control_gradient.py), all 2d+1 evaluations of one iteration batched."""
    start = time.perf_counter()
    x = np.asarray(log_gains, float)
    d = x.size
    batch = jax.jit(jax.vmap(cost))
    c = float(cost(jnp.asarray(x)))
    hist = [c]
    for _ in range(iterations):
        pts = np.concatenate([x[None] + fd * np.eye(d), x[None] - fd * np.eye(d)])
        vals = np.asarray(batch(jnp.asarray(pts)))
        g = (vals[:d] - vals[d:]) / (2 * fd)
        if not np.all(np.isfinite(g)) or np.linalg.norm(g) == 0:
            break
        direction = -g / np.linalg.norm(g)
        s = step
        trials = np.stack([x + s * direction * 0.5**i for i in range(4)])
        tv = np.asarray(batch(jnp.asarray(trials)))
        best = int(np.nanargmin(np.where(np.isfinite(tv), tv, np.inf)))
        if not tv[best] < c:
            step *= 0.25
            hist.append(c)
            continue
        x, c = trials[best], float(tv[best])
        step = min(step * (1.5 if best == 0 else 1.0), 1.0) if best == 0 else s * 0.5**best
        hist.append(c)
    kp, ki, kd = 10.0**x
    return TuneResult(
        x, {"Kp_Pa_per_m": kp, "Ki_Pa_per_m_s": ki, "Kd_Pa_s_per_m": kd}, hist, time.perf_counter() - start
    )


def tune_stepper(
    params: gj.Parameters,
    target: Target,
    t1: float,
    *,
    microsteps: int = 1,
    rates: Sequence[float] = (20.0, 25.0, 50.0),
    leads: Sequence[float] = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4),
    gates: Sequence[float] = (160e3, 200e3, 240e3, float("inf")),
) -> tuple[StepController, float] | None:
    """The step controller's rate (Hz), lead (s) and pressure gate (Pa) by search on the fast model (its cost is
    piecewise constant in them, so a grid, not a gradient; leads 50 ms apart).
    → (best `StepController`, its RMSE m), None where no setting is admissible."""
    plant = Plant.make(params, gj.Config(drive="inverse", t1=t1), microstep=microsteps > 1)
    lim = limits(params)
    best = None
    for rate in rates:
        for lead in leads:
            for gate in gates:
                ctrl = StepController(rate=rate, lead=lead, microsteps=microsteps, pressure_gate=gate)
                res = run_closed_loop(plant, ctrl, target, t1, lim)
                admissible = np.isfinite(res.rmse_m) and not res.pressure_limit_crossed
                if admissible and (best is None or res.rmse_m < best[1]):
                    best = (ctrl, res.rmse_m)
    return best


def plan_steps(
    params: gj.Parameters,
    target: Target,
    t1: float,
    *,
    microsteps: int = 1,
    controller: StepController | None = None,
) -> tuple[StepController, float, Float[np.ndarray, " K"], Float[np.ndarray, " K"]]:
    """The open-loop step schedule planned on the fast model: the tuned closed-loop `StepController`
    (``controller``, default `tune_stepper`'s) runs on the model, and the step counts it issues there are
    the schedule, replayed on the robot without measuring it. The feedback acts on the model's length, so the
    plan inherits the controller's back steps and pressure gate but not its correction of model error.
    → (controller, RMSE m on the model, tick times (s), step counts)."""
    if controller is None:
        controller, _ = tune_stepper(params, target, t1, microsteps=microsteps)
    plant = Plant.make(params, gj.Config(drive="inverse", t1=t1), microstep=microsteps > 1)
    res = run_closed_loop(plant, controller, target, t1, limits(params))
    return controller, res.rmse_m, np.asarray(res.tick_time, float), np.asarray(res.command, float)
