"""What a design must respect on every plausible rig, the rig's `growjax.model.limits.Limits`: the sensed pressure
below the ceiling a margin under the membrane limit, the robot's length inside its stroke and the syringes' travel
inside theirs (and, when a limit is given, the pump platform's speed).

"Every plausible rig" is a set of draws (`draws`): the rig's toleranced parameters within their tolerances
(`growjax.calibration.tolerance.rig_draws`) and θ from its current uncertainty, seeded. In the optimisation the
limits are a penalty on the nominal run widened by the spread the draws would give, linearised (`penalty`, free:
the sensitivities are at hand); on a finished design they are checked by simulating every draw (`check`). The
forward drive's pump is an ideal torque source in the model, so its speed has no limit there:
``max_pump_speed`` is off unless given.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from growjax.calibration import physical_bounds
from growjax.calibration.tolerance import rig_draws
from growjax.design.knowledge import Knowledge
from growjax.design.sensitivity import Sensitivities
from growjax.model import params as gp
from growjax.model.limits import Limits
from growjax.model.signals import Inputs
from growjax.simulation.config import Config
from growjax.simulation.simulate import Breaks, as_arrays, simulate
from growjax.simulation.trajectory import OK

__all__ = ["CHUNK", "DRAWS", "SPREAD", "Check", "check", "draws", "penalty", "stack"]

SPREAD = 2.5  # sds of the linearised spread over the draws the penalty keeps clear of each limit
DRAWS = 32  # rig and θ draws a design is checked on
CHUNK = 128  # runs per compiled batch of the check


def draws(knowledge: Knowledge, n: int = DRAWS, seed: int = 0) -> dict[str, Float[np.ndarray, " n"]]:
    """n draws {qualified name: (n,) SI} of the rig within its tolerances and of θ from N(ln θ̂, Σ_θ), clipped into
    each parameter's physical range; seeded."""
    out = dict(rig_draws(n, knowledge.base, knowledge.tolerances, seed))
    rng = np.random.default_rng([seed, 2])
    theta = knowledge.estimate
    z = rng.multivariate_normal(np.zeros(theta.size), knowledge.covariance, size=n)
    lo, hi = physical_bounds(knowledge.base, knowledge.names, theta)
    z = np.clip(z, lo, hi)
    out.update({name: theta[i] * np.exp(z[:, i]) for i, name in enumerate(knowledge.names)})
    return out


def penalty(
    s: Sensitivities, prior_covariance: Float[Array, "m m"], lim: Limits, spread: float = SPREAD
) -> Float[Array, ""]:
    """Σ over samples of the squared excess (kPa, mm) of the nominal run plus ``spread`` linearised sds over the
    prior (Σ₀ = ``prior_covariance`` (m, m)) above the pressure and length ceilings: 0 inside them (traceable)."""
    # (a floor of 1 nm and 1 mPa keeps the square root's derivative finite where a run does not move)
    sd_l = jnp.sqrt(jnp.einsum("ni,ij,nj->n", s.jac_length, prior_covariance, s.jac_length) + 1e-18)
    sd_p = jnp.sqrt(jnp.einsum("ni,ij,nj->n", s.jac_pressure, prior_covariance, s.jac_pressure) + 1e-6)
    over_p = jax.nn.relu((s.pressure + spread * sd_p - lim.pressure_ceiling) / 1e3)
    over_l = jax.nn.relu((s.length + spread * sd_l - lim.length_ceiling) / 1e-3)
    return jnp.sum(over_p**2) + jnp.sum(over_l**2)


class Check(eqx.Module):
    """A check of inputs over draws, per input (C,): the worst over the draws of the sensed pressure (Pa), the
    length (m), the syringes' travel (m), the platform's speed (m/s), whether every run reached its end, and
    whether all of it is inside the `Limits`; ``length`` and ``pressure`` (C, D, n) the runs
    themselves when kept.

    Attributes:
        peak_pressure: (C,) Pa.
        peak_length: (C,) m.
        peak_syringe: (C,) the syringes' travel, m.
        peak_speed: (C,) the platform's speed, m/s.
        completed: (C,) bool, every run reached its end.
        admissible: (C,) bool, completed and inside the limits.
        length: (C, D, n) m, the runs' length where kept.
        pressure: (C, D, n) Pa, their sensed pressure where kept.
    """

    peak_pressure: np.ndarray
    peak_length: np.ndarray
    peak_syringe: np.ndarray
    peak_speed: np.ndarray
    completed: np.ndarray
    admissible: np.ndarray
    length: np.ndarray | None = None
    pressure: np.ndarray | None = None

    def row(self, i: int) -> dict[str, bool | float]:
        """Input ``i``'s check as a JSON-ready summary (SI, units in the keys)."""
        return {
            "admissible": bool(self.admissible[i]),
            "runs_completed": bool(self.completed[i]),
            "peak_pressure_Pa": float(self.peak_pressure[i]),
            "peak_length_m": float(self.peak_length[i]),
            "peak_syringe_travel_m": float(self.peak_syringe[i]),
            "peak_pump_speed_m_s": float(self.peak_speed[i]),
        }


def stack(inputs: list[Inputs]) -> Inputs:
    """Inputs of one structure stacked into one pytree with a leading axis (C, …) on every leaf."""
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack([jnp.asarray(v) for v in leaves]), *inputs)


def check(
    inputs: Inputs,
    knowledge: Knowledge,
    config: Config,
    ts: Float[ArrayLike, " n"],
    breaks: Breaks,
    lim: Limits,
    drawn: dict[str, Float[np.ndarray, " D"]],
    keep_runs: bool = False,
) -> Check:
    """Simulate every input × draw (the fast configuration, batched ``CHUNK`` runs at a time) and compare the worst
    of each input with ``lim``. ``inputs``: C inputs of one structure stacked (`stack`), sharing their
    ``breaks``; ``drawn`` from `draws`; ``ts`` (n,) s; ``keep_runs``: keep the runs' length and pressure."""
    c = jax.tree_util.tree_leaves(inputs)[0].shape[0]
    d = len(next(iter(drawn.values())))
    names = tuple(drawn)
    values = np.stack([np.asarray(drawn[k], float) for k in names], axis=1)  # (D, r)
    idx_c, idx_d = np.repeat(np.arange(c), d), np.tile(np.arange(d), c)
    total = idx_c.size
    # one batch size from a quarter of a chunk up (short ones padded by wrapping round): the check of one design over
    # the default draws reuses the random batch's program
    size = CHUNK if total >= CHUNK // 4 else total
    out = {k: [] for k in ("length", "pressure", "syringe", "ok")}
    base = as_arrays(knowledge.base)
    for start in range(0, total, size):
        sl = np.arange(start, start + size) % total
        batch = jax.tree_util.tree_map(lambda a, rows=idx_c[sl]: a[rows], inputs)
        res = _runs(base, names, batch, jnp.asarray(values[idx_d[sl]]), config, jnp.asarray(ts), breaks)
        n_real = min(size, total - start)
        for k, v in zip(out, res):
            out[k].append(np.asarray(v)[:n_real])
    length, pressure, syringe, ok = (np.concatenate(out[k]).reshape((c, d) + np.shape(out[k][0])[1:]) for k in out)
    t = np.asarray(ts, float)
    speed = np.abs(np.diff(syringe, axis=-1)) / np.diff(t)
    worst = lambda a: np.max(np.where(np.isfinite(a), a, np.inf), axis=(1, 2))
    peak_p, peak_l, peak_s, peak_v = worst(pressure), worst(length), worst(np.abs(syringe)), worst(speed)
    completed = np.all(ok, axis=1)
    admissible = (
        completed & (peak_p <= lim.pressure_ceiling) & (peak_l <= lim.length_ceiling) & (peak_s <= lim.syringe_stroke)
    )
    if lim.max_pump_speed is not None:
        admissible &= peak_v <= lim.max_pump_speed
    return Check(
        peak_p,
        peak_l,
        peak_s,
        peak_v,
        completed,
        admissible,
        length if keep_runs else None,
        pressure if keep_runs else None,
    )


@eqx.filter_jit
def _runs(base, names, inputs, values, config, ts, breaks):
    def one(i, value):
        p = gp.replace(base, **{k: value[j] for j, k in enumerate(names)})
        tr = simulate(p, i, config, ts=ts, breaks=breaks)
        return tr.length, tr.pressure, tr.syringe_displacement, tr.status == OK

    return jax.vmap(one)(inputs, values)
