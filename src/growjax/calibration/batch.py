"""The runs of a fit simulated together: their problems stacked in groups that one compiled program solves, spread
over the process's devices.

Runs with the same drive, sample count and input structure are stacked (breaks padded to a common length, samples
to a common count) and solved by one program, its runs one after another (``jax.lax.map``), spread over the
process's devices where it has several (`spread`). The Jacobian of each run is taken in its own parameters (its θ,
and its rig's errors where they are parameters of the model); the starts' scout and the rig's secants run the
residuals alone.
"""

from __future__ import annotations

import functools
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from growjax.calibration.layout import Layout
from growjax.calibration.least_squares import linearise, memoised
from growjax.calibration.problem import Problem
from growjax.model import params as gp


class Batch:
    """The runs' problems stacked in groups that one compiled program solves (same configuration and input
    structure): the inputs' break lists padded to a common length, and the samples to a common count with a pressure
    record for every run where one run has it; each run's outputs cut back to its own rows.

    Attributes:
        size: E, the number of runs.
        rig_in_model: whether each run's model parameters are its θ then its rig's errors.
        groups: [(run indices, stacked problem)], one compiled program each.
        simulate_s: s spent in the batched simulations so far.
    """

    def __init__(self, problems, rig_in_model: bool = False):
        self.size = len(problems)
        self.rig_in_model = rig_in_model
        self.sigma_length = float(problems[0].sigma_length)
        self.n_len = [int(pr.times.size) for pr in problems]
        problems, self.rows = pad_samples(pad_breaks(problems))
        groups: dict = {}
        for e, pr in enumerate(problems):
            leaves, tree = jax.tree_util.tree_flatten(pr)
            key = (tree, tuple(np.shape(x) for x in leaves))
            groups.setdefault(key, []).append(e)
        # a run alone keeps its own leaves (Python numbers in its inputs stay constants of its program, as in a
        # fit of that run by itself); runs together are stacked
        self.groups = [
            (members, stack([problems[e] for e in members]) if len(members) > 1 else problems[members[0]])
            for members in groups.values()
        ]
        self.simulate_s = 0.0
        self._at = memoised(lambda z, layout: self._run(linearise_runs, z, layout))

    def linearised(self, z, layout: Layout, stacked=None):
        """[(r (m_e,), J (m_e, p))] per run at the set's coordinates z (P,) (the last few points kept: the fit asks
        for a point again where one solver's end is the next one's start). With the rig's errors in the model
        (`rig_in_model`), z may be w = (z, b) (P + Q,) and J is (m_e, p + q)."""
        if self.rig_in_model and np.size(z) == len(layout.labels):  # the rig nominal: one point with w = (z, 0)
            z = np.concatenate([np.asarray(z, float), np.zeros(len(layout.rig_labels))])
        if stacked is None:
            return self._at(z, layout)
        return self._run(linearise_runs, z, layout, stacked)

    def residuals(self, z, layout: Layout, stacked=None):
        """[(r (m_e,), None)] per run at the set's coordinates z (P,): the runs alone, no tangents."""
        return self._run(residuals_runs, z, layout, stacked)

    def scout(self, zs, layout: Layout) -> list:
        """[[(r (m_e,), ok ())] per run] per point of ``zs`` (K, P): every run at every point in one call of the
        runs' program per group (K copies of each run); r NaN and ok False where a run did not succeed."""
        clock = time.perf_counter()
        k = len(zs)
        z_local = [self._local(z, layout) for z in zs]
        out = [[None] * self.size for _ in range(k)]
        for members, problem in self.groups:
            stacked = problem if len(members) > 1 else stack([problem])
            copies = jax.tree_util.tree_map(lambda x: jnp.concatenate([x] * k), stacked)
            z_all = np.concatenate([z[members] for z in z_local])
            r, ok = (np.asarray(x) for x in spread(scout_runs, jnp.asarray(z_all), copies))
            for j in range(k):
                for i, e in enumerate(members):
                    out[j][e] = (r[j * len(members) + i][self.rows[e]], bool(ok[j * len(members) + i]))
        self.simulate_s += time.perf_counter() - clock
        return out

    def _local(self, z, layout: Layout) -> np.ndarray:
        """Each run's model coordinates (E, p) (with the rig in the model, (E, p + q)) at the set's z (P,) or w."""
        p_all = len(layout.labels)
        z_local = np.asarray(z)[:p_all][layout.index] + layout.offset
        if self.rig_in_model:  # w = (z, b): each run's rig errors after its θ (b = 0 when only z given)
            b = np.asarray(z)[p_all:] if np.size(z) > p_all else np.zeros(len(layout.rig_labels))
            z_local = np.concatenate([z_local, b[layout.rig_index]], axis=1)
        return z_local

    def _run(self, program, z, layout: Layout, stacked=None):
        clock = time.perf_counter()
        z_local = self._local(z, layout)
        out = [None] * self.size
        for k, (members, problem) in enumerate(self.groups):
            pr = problem if stacked is None else stacked[k]
            results = tuple(
                None if x is None else np.asarray(x)
                for x in spread(program, jnp.asarray(z_local[members]), pr, len(members) > 1)
            )
            for i, e in enumerate(members):
                out[e] = tuple(None if x is None else x[i][self.rows[e]] for x in results)
        self.simulate_s += time.perf_counter() - clock
        return out

    def sensitivities(self, z, layout: Layout, tol: dict, central: bool = False) -> list:
        """Per run g (n_e, q): the length's change, m, per unit ln ψ of each toleranced parameter (the secant from
        ψ to ψ·e^u, or with ``central`` from ψ·e^(−u/2) to ψ·e^(u/2), as `growjax.calibration.tolerance.sensitivity`;
        every run of a group in one batched solve).

        Raises:
            RuntimeError: a run failed while the sensitivities were measured.
        """
        cols = [[] for _ in range(self.size)]
        lo_hi = (-0.5, 0.5) if central else (0.0, 1.0)
        r0 = None if central else self.linearised(z, layout)  # the runs at z: the fit has them already
        for name, u in tol.items():
            ends = []
            for f in lo_hi:
                if f == 0.0:
                    ends.append(r0)
                    continue
                shifted = [
                    eqx.tree_at(
                        lambda pr: pr.base,
                        problem,
                        gp.replace(problem.base, **{name: gp.get(problem.base, name) * np.exp(f * u)}),
                    )
                    for _, problem in self.groups
                ]
                ends.append(self.residuals(z, layout, shifted))
            for e in range(self.size):
                n = self.n_len[e]
                cols[e].append((ends[1][e][0][:n] - ends[0][e][0][:n]) * self.sigma_length / u)
        g = [np.stack(c, axis=1) for c in cols]
        if not all(np.all(np.isfinite(x)) for x in g):
            raise RuntimeError("the model failed while measuring the rig's tolerance sensitivities")
        return g


# The runs of a program follow one another (``jax.lax.map``), each with its own adaptive steps: vmapped, every run
# would keep step with the slowest (a linearisation of benchmarks/set_speed.py's eight 10 s runs on two cores:
# 0.61 s mapped, 0.75 s vmapped).


def linearise_runs(z_local, problems: Problem, stacked: bool = True):
    """Residuals (E, m) and Jacobians (E, m, p) of stacked problems (or of one problem, not ``stacked``): each
    run's forward-mode linearisation, one run after another in one program."""
    return _each(lambda z, pr: linearise(pr.residuals, z), z_local, problems, stacked)


def residuals_runs(z_local, problems: Problem, stacked: bool = True):
    """Residuals (E, m) of stacked problems (or of one, not ``stacked``), and None for the Jacobian: the runs one
    after another in one program."""
    return _each(lambda z, pr: pr.residuals(z), z_local, problems, stacked), None


def scout_runs(z_local, problems: Problem, stacked: bool = True):
    """Residuals (E, m), NaN where a run failed, and whether each run succeeded (E,), of stacked problems (or of
    one, not ``stacked``): the runs one after another in one program."""
    return _each(lambda z, pr: pr.simulated(z), z_local, problems, stacked)


def _each(program, z_local, problems: Problem, stacked: bool):
    """``program(z, problem)`` of each stacked run, one after another (``jax.lax.map``), or of the one problem
    ``problems`` (not ``stacked``: z_local (1, p)), with a leading axis of one."""
    if not stacked:
        return jax.tree_util.tree_map(lambda x: x[None], program(z_local[0], problems))
    return jax.lax.map(lambda a: program(*a), (z_local, problems))


@eqx.filter_jit
def on_one_device(program, z_local, problems: Problem, stacked: bool = True):
    """``program`` on the E stacked runs (or on one problem, not ``stacked``) as one program on the default
    device."""
    return program(z_local, problems, stacked)


def spread(program, z_local, problems: Problem, stacked: bool = True):
    """``program`` (`linearise_runs`, `residuals_runs` or `scout_runs`) on the E stacked runs, spread over the
    process's devices: each device solves its share of the runs in one program (``jax.shard_map``). On a CPU with
    several cores exposed as devices (``jax_num_cpu_devices``) the shares run on different cores at once. With one
    run (or one problem, not ``stacked``), or one device, it is the program itself."""
    n = int(z_local.shape[0])
    d = min(len(jax.devices()), n)
    if d < 2 or not stacked:
        return on_one_device(program, z_local, problems, stacked)
    arrays, static = eqx.partition(problems, eqx.is_array)
    size = -(-n // d) * d
    if size > n:  # padded with copies of the first run to fill every device's share
        take = jnp.asarray(np.r_[np.arange(n), np.zeros(size - n, dtype=int)])
        z_local, arrays = z_local[take], jax.tree_util.tree_map(lambda x: x[take], arrays)
    out = sharded(program, mesh(d), static, z_local, arrays)
    return out if size == n else jax.tree_util.tree_map(lambda x: x[:n], out)


@functools.cache
def mesh(d: int):
    """The mesh of the process's first ``d`` devices along the axis ``"runs"``."""
    return jax.sharding.Mesh(np.asarray(jax.devices()[:d]), ("runs",))


@eqx.filter_jit
def sharded(program, mesh, static, z_local, arrays):
    """``program`` on the runs (``z_local``, ``arrays`` joined to ``static``) split over ``mesh``'s devices."""

    def share(z, a):
        return program(z, eqx.combine(a, static))

    runs = jax.sharding.PartitionSpec("runs")
    # check_vma off: the solver's loop starts from constants that are the same on every device
    return jax.shard_map(share, mesh=mesh, in_specs=runs, out_specs=runs, check_vma=False)(z_local, arrays)


def stack(problems):
    """Problems of one tree structure and shapes stacked along a leading axis."""
    return jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *problems)


def pad_breaks(problems):
    """Problems of one configuration with their break lists padded to the longest (beyond t1: never reached)."""
    out = list(problems)
    for members in _by_config(problems):
        sizes = [max(problems[e].breaks[k].size for e in members) for k in range(2)]
        for e in members:
            pr = problems[e]
            padded = tuple(
                jnp.concatenate([b, jnp.full(s - b.size, pr.config.t1 + 1.0)]) for b, s in zip(pr.breaks, sizes)
            )
            out[e] = eqx.tree_at(lambda p: p.breaks, pr, padded)
    return out


def _by_config(problems) -> list:
    """The indices of the problems, grouped by configuration (a group may share one compiled program)."""
    groups: dict = {}
    for e, pr in enumerate(problems):
        groups.setdefault(pr.config, []).append(e)
    return list(groups.values())


def pad_samples(problems):
    """Problems of one configuration padded to one row layout, and the rows (indices) each keeps of it.

    The samples are padded to the most of any run (the last one repeated: a copy of a saved point), and where one
    run records the pressure every run gets a pressure record (zeros where it has none). A padded run's residuals
    are (M,) or (2M,): its own rows are its first m_e, then (with the pressure) M to M + m_e. Runs measured alike
    and runs with and without the pressure sensor are then one compiled program instead of one per shape.
    """
    out, rows = list(problems), [None] * len(problems)
    for members in _by_config(problems):
        size = max(int(np.size(problems[e].times)) for e in members)
        sensed = any(problems[e].pressure is not None for e in members)
        for e in members:
            pr, m = problems[e], int(np.size(problems[e].times))
            pad = lambda a, k=size - m: jnp.concatenate([jnp.asarray(a), jnp.repeat(jnp.asarray(a)[-1:], k)])  # noqa: E731
            pressure = pad(pr.pressure) if pr.pressure is not None else jnp.zeros(size) if sensed else None
            weight = None
            if sensed:  # the padded rows and a run without the pressure score none
                own = pr.pressure_weight
                if own is None:
                    own = jnp.ones(m) if pr.pressure is not None else jnp.zeros(m)
                weight = jnp.concatenate([jnp.asarray(own, float), jnp.zeros(size - m)])
            out[e] = eqx.tree_at(
                lambda p: (p.times, p.length, p.pressure, p.pressure_weight),
                pr,
                (pad(pr.times), pad(pr.length), pressure, weight),
                is_leaf=lambda x: x is None,
            )
            rows[e] = np.r_[np.arange(m), size + np.arange(m)] if pr.pressure is not None else np.arange(m)
    return out, rows


__all__ = [
    "Batch",
    "linearise_runs",
    "mesh",
    "on_one_device",
    "pad_breaks",
    "pad_samples",
    "residuals_runs",
    "scout_runs",
    "sharded",
    "spread",
    "stack",
]
