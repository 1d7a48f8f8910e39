"""Running a discovery's fits: the models of one round as data of one compiled program, their starts, fits run
``workers`` at a time, and the counts of fits and linearisations."""

from __future__ import annotations

import concurrent.futures
import math
import os

import jax.numpy as jnp
import numpy as np

from ._candidates import (
    BASE_START_FACTORS,
    START_FRACTIONS,
    CandidateFit,
    Candidates,
    _summarise,
    fit_model,
)
from ._scoring import noise_from_differences

LR_RESOLUTION = 0.1  # 2ΔlogL below which a fit's progress no longer counts (the threshold is ~6)


class Fitter:
    """The fits of one discovery on ``problem`` (:class:`Candidates`): each model a (mask, select, z_fixed) of the
    superset, every model with the same number of fitted coordinates q through one compiled program. Counts the
    fits run (``fits``) and the model linearisations over them (``linearisations``); ``added_index``: the
    candidates added so far (their fits start from their current values, not from a new effect's starts)."""

    def __init__(self, problem: Candidates, length, multistart: bool, workers: int, progress: bool, max_steps: int):
        self.problem, self.workers, self.progress, self.max_steps = problem, workers, progress, max_steps
        self.p, self.k_all = len(problem.base_names), len(problem.effect_names)
        # u of each start (K, starts): η = s·softplus(u) with s a tenth of the top; signed effects start at 0, ±5 %.
        fractions = START_FRACTIONS if multistart else START_FRACTIONS[:1]
        self.u_starts = np.stack(
            [
                np.where(np.asarray(problem.signed), u_signed, math.log(math.expm1(10.0 * f)))
                for f, u_signed in zip(fractions, (0.0, -0.5, 0.5))
            ],
            axis=1,
        )
        # a fit's cost (½RSS, mm²) worth LR_RESOLUTION of 2ΔlogL, σ from the data's second differences (var 6σ²)
        sigma_data = noise_from_differences(np.diff(length)) / math.sqrt(3.0)
        self.resolution = 0.5 * LR_RESOLUTION * (sigma_data / 1e-3) ** 2
        self.added_index = []
        self.compiled = set()  # the numbers of fitted coordinates q whose program exists (one compiled program per q)
        self.fits, self.linearisations = 0, 0  # fits run, and model runs (residuals, Jacobian) over them: a run's time

    def model(self, effects_on, fit_base: bool, z_now, start: int | None = 0):
        """(w0 (q,), mask (K,), select (p + K, q), z_fixed (p + K,)) of a model with ``effects_on`` fitted, a new
        candidate starting from its ``start``-th start (None: from its value in ``z_now``). q = p + the effects
        on, at least one (the base model shares the first round's program)."""
        p, k_all = self.p, self.k_all
        q = p + max(len(effects_on), 1)
        mask, select = np.zeros(k_all), np.zeros((p + k_all, q))
        z_fixed, w0 = np.array(z_now, float), np.zeros(q)
        if fit_base:
            select[np.arange(p), np.arange(p)] = 1.0
            w0[:p], z_fixed[:p] = z_fixed[:p], 0.0
        for col, k in enumerate(effects_on):
            mask[k] = 1.0
            select[p + k, p + col] = 1.0
            w0[p + col] = z_fixed[p + k] if (k in self.added_index or start is None) else self.u_starts[k, start]
            z_fixed[p + k] = 0.0
        return w0, mask, select, z_fixed

    def _jobs(self, specs, warm) -> list:
        """(spec index, model) of every start of every spec (see :meth:`batch`)."""
        jobs = []
        for i, (effects_on, fit_base, z_now) in enumerate(specs):
            new = [k for k in effects_on if k not in self.added_index]
            base_only = fit_base and not effects_on and not self.added_index  # the base model: its own starts
            if i in warm:
                starts = [None]
            elif base_only:
                starts = range(len(BASE_START_FACTORS))
            else:
                starts = range(self.u_starts.shape[1]) if new else [0]
            for start in starts:
                if base_only:
                    z_start = np.array(z_now, float)
                    z_start[: self.p] += math.log(BASE_START_FACTORS[start])
                    jobs.append((i, self.model(effects_on, fit_base, z_start, None)))
                else:
                    jobs.append((i, self.model(effects_on, fit_base, z_now, start)))
        return jobs

    def batch(self, specs, desc: str, warm=()) -> list:
        """Fit the models (``specs``: arguments of :meth:`model`, all with the same q) through one compiled program,
        ``workers`` fits at a time; a model with a new candidate from each of its starts, keeping the lowest misfit (a
        model whose index is in ``warm``: from its value in the spec's ``z_now`` only). Each fit: (z (p + K,),
        residuals (m,) mm, Jacobian (m, q), converged, its model, pressure (m,) Pa)."""
        jobs = self._jobs(specs, warm)

        def run(job):
            m = job[1]
            z, r, jac, ok, pressure, runs = fit_model(
                self.problem, *(jnp.asarray(a) for a in m), self.max_steps, self.resolution
            )
            return job[0], (np.asarray(z), np.asarray(r), np.asarray(jac), bool(ok), m, pressure), runs

        fits = [[] for _ in specs]
        q = jobs[0][1][0].size if jobs else None  # the program these fits run: new, it is compiled by the first alone
        for i, fitted, runs in _map_jobs(
            run, jobs, self.workers, self.progress, desc, first_alone=q not in self.compiled
        ):
            fits[i].append(fitted)
            self.linearisations += runs
        self.compiled.add(q)
        self.fits += len(jobs)
        return [min(f, key=lambda f: float(f[1] @ f[1])) for f in fits]

    def summarise(self, out, sigma: float, effects: tuple) -> CandidateFit:
        """The :class:`CandidateFit` of one of :meth:`batch`'s fits at noise ``sigma`` (m)."""
        z, r, jac, ok, (_, mask, select, _), _ = out
        return _summarise(self.problem, z, r, jac, mask, select, sigma, ok, effects)


def _map_jobs(run, jobs, workers: int, progress: bool, desc: str, first_alone: bool) -> list:
    """[``run(job)`` for every job], ``workers`` at a time on threads (XLA runs a compiled program without the
    GIL, so the fits of one process share the CPU's cores). ``first_alone``: the first job runs before the
    others start, so that their program is compiled once, not once per thread."""
    bar = _bar(progress, desc, len(jobs))
    results = []
    if jobs and (first_alone or workers == 1):
        results.append(run(jobs[0]))
        bar.update(1)
    rest = jobs[len(results) :]
    if workers > 1 and len(rest) > 1:
        with concurrent.futures.ThreadPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(run, job) for job in rest]
            for _ in concurrent.futures.as_completed(futures):
                bar.update(1)
            results += [f.result() for f in futures]
    else:
        for job in rest:
            results.append(run(job))
            bar.update(1)
    bar.close()
    return results


def _cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _bar(enabled: bool, desc: str, total: int):
    """Progress of ``total`` fits when ``enabled``: a bar on a terminal, a line every ~10 % elsewhere."""
    from growjax import progress as prog

    return prog.bar(total, desc, "fit", enabled)
