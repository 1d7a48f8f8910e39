"""Search of the design space: a batch of random admissible inputs, and gradient descent (Adam) through the model
from several starts (the forward drive's demand) or a local search over the choices (the stepper's schedule, whose
criterion is piecewise constant: no gradient to follow).

The random batch is the baseline a design must beat and the source of the starts: n random designs
(`growjax.design.space.DesignSpace.random`) are simulated over every draw of the rig and θ in batches
(`growjax.design.constraints.check`), the inadmissible ones dropped (more are drawn, a few rounds at most,
until n pass), and the rest scored by the criterion. The optimiser then descends from the best of them: its
design is the best iterate it met, so it is never worse than its start.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from jaxtyping import ArrayLike, Float

import growjax.design.constraints as dcon
import growjax.design.discrimination as ddis
import growjax.design.problem as dprob
from growjax import progress as prog
from growjax.design.knowledge import Knowledge
from growjax.design.space import DesignSpace, StepperSpace

__all__ = [
    "BATCH",
    "GRADIENTS",
    "ITERATIONS",
    "LEARNING_RATE",
    "ROUNDS",
    "Descent",
    "RandomBatch",
    "adam",
    "local_search",
    "multistart",
    "neighbours",
    "random_admissible",
]

ITERATIONS = 15  # Adam steps per start
LEARNING_RATE = 0.2  # in the logits of the demand: ~5 % of p_max per step at most, early on
ROUNDS = 4  # rounds of random draws for n admissible inputs


@dataclasses.dataclass
class Descent:
    """One start's descent.

    Attributes:
        x: (K,) the best design met.
        value: its objective.
        history: the objective at every iterate.
        start: (K,) the start.
    """

    x: np.ndarray
    value: float
    history: list
    start: np.ndarray


def adam(
    value_and_grad: Callable[[np.ndarray], tuple[ArrayLike, ArrayLike]],
    x0: Float[ArrayLike, " K"],
    iterations: int = ITERATIONS,
    learning_rate: float = LEARNING_RATE,
    beta1: float = 0.9,
    beta2: float = 0.999,
    eps: float = 1e-8,
    progress: Any = None,
) -> Descent:
    """Adam on ``value_and_grad(x) → (f, ∇f)`` from ``x0`` (K,), the step decaying linearly to a tenth over
    ``iterations``. A non-finite value (the model failed there) sends the search back to the best point with half
    the step. ``progress``: a progress object (`growjax.progress.bar`) counting the evaluations. Returns the best
    iterate (the start included)."""
    x = np.asarray(x0, float).copy()
    m, v = np.zeros_like(x), np.zeros_like(x)
    best_x, best_f, history = x.copy(), np.inf, []
    lr, k = learning_rate, 0
    for it in range(iterations + 1):
        f, g = (np.asarray(a, float) for a in value_and_grad(x))
        f = float(f)
        history.append(f)
        if progress is not None:
            progress.update(1)
        ok = np.isfinite(f) and np.all(np.isfinite(g))
        if ok and f < best_f:
            best_x, best_f = x.copy(), f
        if it == iterations:
            break
        if not ok:
            x, m, v, k, lr = best_x.copy(), np.zeros_like(x), np.zeros_like(x), 0, 0.5 * lr
            continue
        k += 1
        m = beta1 * m + (1 - beta1) * g
        v = beta2 * v + (1 - beta2) * g * g
        step = lr * (1.0 - 0.9 * it / max(iterations, 1))
        x = x - step * (m / (1 - beta1**k)) / (np.sqrt(v / (1 - beta2**k)) + eps)
    return Descent(best_x, best_f, history, np.asarray(x0, float))


GRADIENTS = ("differences", "jax")


def multistart(
    problem: dprob.DesignProblem,
    starts: Float[ArrayLike, "S K"],
    iterations: int = ITERATIONS,
    learning_rate: float = LEARNING_RATE,
    gradient: str = "differences",
    progress: bool = False,
) -> list[Descent]:
    """`adam` on the problem's objective from each row of ``starts`` (S, K − 1), best first. ``gradient``:
    ``"differences"``, the slope over a step of the demand (`growjax.design.problem.smoothed_gradient`), or
    ``"jax"``, the exact derivative by forward mode through the model
    (`growjax.design.problem.value_and_gradient`)."""
    if gradient not in GRADIENTS:
        raise ValueError(f"gradient must be one of {GRADIENTS}, got {gradient!r}")
    starts = np.atleast_2d(np.asarray(starts, float))

    def vg(x):
        if gradient == "jax":
            exact = ddis.value_and_gradient if isinstance(problem, ddis.Discrimination) else dprob.value_and_gradient
            return exact(problem, np.asarray(x))
        return dprob.smoothed_gradient(problem, np.asarray(x))

    runs = []
    with prog.bar(len(starts) * (iterations + 1), "design: descent", "step", progress) as bar:
        for x0 in starts:
            runs.append(adam(vg, x0, iterations, learning_rate, progress=bar))
    return sorted(runs, key=lambda r: r.value)


def neighbours(space: StepperSpace, x: Float[ArrayLike, " N"]) -> Float[np.ndarray, "M N"]:
    """The stepper schedules one change from x (N,): one edge's choice set to either of the other two, or two
    neighbouring edges' different choices swapped (a step moved by one period); those whose count stays ≥ 0,
    each once (M, N)."""
    x = np.asarray(x, float)
    out = []
    for k in range(x.size):
        for e in (-1.0, 0.0, 1.0):
            if e != x[k]:
                y = x.copy()
                y[k] = e
                out.append(y)
        if k + 1 < x.size and x[k] != x[k + 1]:
            y = x.copy()
            y[k], y[k + 1] = x[k + 1], x[k]
            out.append(y)
    out = [y for y in out if np.all(np.cumsum(y) >= 0)]
    return np.unique(np.asarray(out), axis=0) if out else np.zeros((0, x.size))


BATCH = 8  # neighbours scored together in the local search (one compiled evaluation each, a thread per core)


def local_search(
    problem: dprob.DesignProblem,
    space: StepperSpace,
    starts: Float[ArrayLike, "S N"],
    moves: int = ITERATIONS,
    seed: int = 0,
    batch: int = BATCH,
    progress: bool = False,
) -> list[Descent]:
    """From each row of ``starts`` (S, N), at most ``moves`` moves of a first-improvement search over the stepper's
    `neighbours`: they are scored ``batch`` at a time in a seeded random order
    (`growjax.design.problem.values`), and the first batch holding one better than the incumbent moves the
    search to the best of that batch. A move costs a batch or two while most neighbours improve, where a
    steepest step would score all ~3N; when no neighbour improves, the schedule is a local optimum and the search
    stops. Best first."""
    starts = np.atleast_2d(np.asarray(starts, float))
    rng = np.random.default_rng([seed, 5])
    runs = []
    with prog.bar(len(starts) * moves, "design: local search", "move", progress) as bar:
        for x0 in starts:
            x, f = x0.copy(), float(dprob.values(problem, x0[None])[0])
            history = [f]
            for _ in range(moves):
                cands = neighbours(space, x)
                cands = cands[rng.permutation(len(cands))]
                for lo in range(0, len(cands), batch):
                    v = dprob.values(problem, cands[lo : lo + batch])
                    i = int(np.argmin(v))
                    if v[i] < f:
                        x, f = cands[lo + i], float(v[i])
                        break
                else:  # no neighbour improves: a local optimum
                    break
                history.append(f)
                bar.update(1)
            runs.append(Descent(x, f, history, x0))
    return sorted(runs, key=lambda r: r.value)


@dataclasses.dataclass
class RandomBatch:
    """Random admissible inputs.

    Attributes:
        designs: (N, K) the designs.
        criterion: (N,) their criterion.
        drawn: how many inputs were drawn to find them.
        wall_s: the wall time, s.
    """

    designs: np.ndarray
    criterion: np.ndarray
    drawn: int
    wall_s: float

    @property
    def best(self) -> int:
        """Index of the best (lowest criterion) admissible input; one without a criterion (NaN) is never the best."""
        return int(np.argmin(np.where(np.isfinite(self.criterion), self.criterion, np.inf)))

    def order(self) -> np.ndarray:
        """The designs' indices, best (lowest criterion) first."""
        return np.argsort(self.criterion)


def random_admissible(
    problem: dprob.DesignProblem,
    space: DesignSpace,
    knowledge: Knowledge,
    n: int,
    seed: int = 0,
    drawn: dict | None = None,
    rounds: int = ROUNDS,
    progress: bool = False,
) -> RandomBatch:
    """n random admissible inputs, scored: each random design simulated over every draw (``drawn``, default
    `growjax.design.constraints.draws` of ``knowledge``, seeded) in batches, the inadmissible dropped, more
    drawn (at most ``rounds`` rounds) until n pass; then the criterion of each (one compiled evaluation per
    input, one per CPU core at a time). Fewer than n where the rounds run out; ValueError where none is admissible."""
    clock = time.perf_counter()
    rng = np.random.default_rng([seed, 4])
    drawn = drawn if drawn is not None else dcon.draws(knowledge, seed=seed)
    kept, total = [], 0
    breaks = space.breaks()
    for _ in range(rounds):
        batch = space.random(max(n - len(kept), 1) * 2 if kept or total else n, rng)
        total += len(batch)
        res = dcon.check(
            dcon.stack([space.inputs(x) for x in batch]),
            knowledge,
            space.config(),
            space.times,
            breaks,
            problem.limits,
            drawn,
        )
        kept += [x for x, ok in zip(batch, res.admissible) if ok]
        if len(kept) >= n:
            break
    if not kept:
        raise ValueError(
            f"none of {total} random inputs in [0, {space.p_max / 1e3:.0f} kPa] stays inside the limits "
            "for every draw of the rig: lower p_max or shorten the run"
        )
    designs = np.asarray(kept[:n])
    prog.note(f"design: scoring {len(designs)} random admissible inputs", progress)
    crit = dprob.evaluate_many(problem, designs)[:, 0]
    crit = np.where(np.isfinite(crit), crit, np.inf)
    return RandomBatch(designs, crit, total, time.perf_counter() - clock)
