"""growjax's Levenberg–Marquardt engine against optimistix's least-squares solvers on the workflows' problems.

Run: ``python benchmarks/least_squares.py [--repeat 3] [--cases fit_Y,fit_Y_kp,profile]
[--solvers engine,lm,lm_best,dogleg,dogleg_best] [--out benchmarks/results/least_squares.json]``
(about 11 minutes on two busy cores). ``--solvers lm_linearize`` adds optimistix's Levenberg–Marquardt on the
residuals as they are (its own ``jax.linearize`` of the model), e.g. ``--cases fit_Y --solvers lm_linearize
--out benchmarks/results/least_squares_linearize.json``.

Problems, each from one start:

* ``fit_Y``, ``fit_Y_kp``: the fit's first stage (least squares, before the discrepancy) on the shipped synthetic
  experiment, forward drive, 0–10 s, length only: ``growjax.calibration.make_problem``'s residuals (units of 1 mm) in
  z = ln(θ/θ_ref) for Y, and for Y with the pressure loop's proportional gain ``pid.proportional``; the start
  30 % above the reference values. The engine runs as the fit runs it (``growjax.calibration.problem.linearised``, the
  physical bounds, ``LM_TOLERANCE``).
* ``profile``: the control profile's problem as ``growjax.control.optimize_profile`` poses it (its residual
  function is local to it, so it is built here from the module's pieces: ``profile_inputs``,
  ``growjax.simulation.simulate``, the same residual rows, scaling, first guess, bounds [0, the demand limit] and
  ``MAX_STEP``): the forward drive's demand on knots every 0.5 s over 0–5 s tracking the shipped
  experiment's length. The engine runs as the workflow runs it (trial points scored by one solve, linearised
  once accepted).

Solvers: the engine, and ``optimistix.least_squares`` with ``LevenbergMarquardt`` and ``Dogleg``, each bare and
wrapped in ``BestSoFarLeastSquares``, at rtol = atol = ``LM_TOLERANCE``, at most ``--max-steps`` steps. Their
residuals' JVP is the engine's linearisation (one solve carrying every sensitivity, J·v): the same model
derivative for all, and one that Dogleg can transpose (the fast solver's own tangents cannot be). optimistix
has no bounds: its point is checked against the workflow's box. Each solver runs once cold (the first call,
compilation included; in one process, in the order listed, so a later first call may reuse traces of the
model an earlier one made) and ``--repeat`` times warm; runs alternate between solvers, so a drift of the
machine's speed falls on all alike. Recorded: wall times (first, median warm), steps (the engine's accepted
steps, and its evaluations: calls of the residuals or their linearisation; optimistix's ``num_steps``, one
linearisation each), the final cost ½‖r‖² (every solver's point scored by the same plain solve),
convergence, whether the point lies in the workflow's box, for the fits the distance of each point from the
engine's (the largest, in Gauss–Newton standard errors with the noise estimated from the residuals), and the
cost's own noise (at the engine's point, the relative difference between the solve carrying sensitivities
and the plain solve). Verdict per problem:
an optimistix solver replaces the engine where it converged, its cost is no more than the engine's by a
relative 1e-6, its median warm time is within 1.5× the engine's, and its point lies inside the box.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import growjax as gj
from growjax import calibration as cal
from growjax import control as gc
from growjax.calibration.least_squares import levenberg_marquardt, linearise
from growjax.calibration.problem import linearised as fit_linearised
from growjax.control import profile as cp
from growjax.data import datasets as _data
from growjax.data import experiment as ex

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment

CASES = ("fit_Y", "fit_Y_kp", "profile")
# key: label. ``lm_linearize`` (optimistix's own jax.linearize of the residuals) is not in the default run.
SOLVERS = {
    "engine": "engine",
    "lm": "optimistix LM",
    "lm_best": "optimistix LM, best so far",
    "dogleg": "optimistix Dogleg",
    "dogleg_best": "optimistix Dogleg, best so far",
    "lm_linearize": "optimistix LM, jax.linearize",
}
DEFAULT_SOLVERS = ("engine", "lm", "lm_best", "dogleg", "dogleg_best")
SAME_COST = 1e-6  # relative: an optimistix cost above the engine's by more than this is a worse fit
WITHIN = 1.5  # the warm-time ratio under which optimistix would replace the engine


class Case:
    """One problem: the residual function r(x) (jittable), the start x0, the box (lower, upper) and the
    engine's run as its workflow calls it, → (x, converged, accepted steps, evaluations)."""

    statistical = False

    def __init__(self, label, residuals, x0, bounds, engine, parameters, linearised):
        self.label, self.residuals, self.x0, self.bounds = label, residuals, np.asarray(x0, float), bounds
        self.engine, self.parameters, self.linearised = engine, parameters, linearised
        self.scored = jax.jit(lambda x: residuals(x))

    def cost(self, x) -> float:
        r = np.asarray(self.scored(jnp.asarray(x)))
        return 0.5 * float(r @ r)


class Counter:
    """Counts a residual or linearisation function's calls and the accepted ones (cost ≤ the best so far)."""

    def __init__(self, fn):
        self.fn, self.calls, self.accepted, self.best = fn, 0, -1, np.inf

    def __call__(self, x):
        out = self.fn(x)
        r = np.asarray(out[0] if isinstance(out, tuple) else out)
        self.calls += 1
        cost = 0.5 * float(r @ r)
        if cost <= self.best:
            self.best, self.accepted = cost, self.accepted + 1
        return out


def fit_case(label, names, max_steps):
    exp = ex.read(_data.default_data_path()).window(10.0 + 1e-9)
    base, config = gj.reference("forward"), gj.Config(t1=10.0)
    inputs = ex.to_inputs(exp, "forward", base, config.t0, config.t1)
    problem = cal.make_problem(base, names, inputs, config.replace(adjoint="forward"), exp.time, exp["robot_length_m"])
    refs = np.asarray(problem.refs)
    bounds = cal.physical_bounds(base, problem.names, refs)

    def linearised(z):  # the fit's compiled linearisation
        return fit_linearised(jnp.asarray(z), problem)

    def engine(x0):
        lin = Counter(linearised)
        z, _, ok, _, _ = levenberg_marquardt(lin, x0, max_steps, cal.LM_TOLERANCE, bounds=bounds)
        return z, ok, lin.accepted, lin.calls

    def estimate(z):
        return dict(zip(problem.names, map(float, refs * np.exp(z))))

    case = Case(label, problem.residuals, np.full(len(names), np.log(1.3)), bounds, engine, estimate, linearised)
    case.statistical = True  # a fit: points compared in standard errors
    case.description = (
        f"fit's first stage, free {', '.join(problem.names)}, {problem.times.size} length samples, "
        "start 30 % above the reference"
    )
    return case


def profile_case(max_steps, t_end=5.0, knot_dt=0.5, smooth=1e-3):
    """``optimize_profile``'s residuals, first guess and box (lead 0, its defaults otherwise), rebuilt here."""
    target = gc.target_from_experiment(ex.read(_data.default_data_path()), t_end)
    params = gc.plant_params("forward", target)
    lim = gj.limits(params)
    config = gj.Config(t1=t_end, adjoint="forward")
    knots = np.arange(0.0, t_end + knot_dt - 1e-9, knot_dt)
    ts = target.time[(target.time >= config.t0) & (target.time <= t_end)]
    ref = jnp.asarray(target.at(ts))
    breaks = gj.input_breaks(cp.profile_inputs(target, knots, np.full(knots.size, 120e3)), config)
    scale = 1e5

    def residuals(x, args=None):
        tr = gj.simulate(params, cp.profile_inputs(target, knots, x * scale), config, ts=ts, breaks=breaks)
        err = (tr.length - ref) / 1e-3
        over = jax.nn.relu(tr.pressure - lim.pressure_ceiling) / 1e3
        return jnp.concatenate([err, np.sqrt(smooth) * jnp.diff(x) * 10.0, over])

    hi = lim.pressure_ceiling / scale
    speed = np.gradient(target.at(knots + knot_dt), knots)
    x0 = np.clip(0.6 + 12.0 * np.maximum(speed, 0.0) / 1e-2 * 0.1, 0.0, hi)
    bounds = (np.zeros(knots.size), np.full(knots.size, hi))
    scored, linearised = jax.jit(residuals), jax.jit(lambda x: linearise(residuals, x))

    def engine(x):
        score, lin = Counter(scored), Counter(linearised)
        x, _, ok, _, _ = levenberg_marquardt(
            lin, x, max_steps=max_steps, bounds=bounds, max_move=cp.MAX_STEP / scale, residuals=score
        )
        return x, ok, lin.calls - 1, score.calls + lin.calls  # one linearisation per accepted step, and the first

    def demand(x):
        return {"demand_kPa": [round(float(v) * scale / 1e3, 1) for v in x]}

    case = Case("profile", residuals, x0, bounds, engine, demand, linearised)
    case.description = (
        f"control profile, {knots.size} knots every {knot_dt:g} s over 0–{t_end:g} s, "
        f"{ts.size} length samples, the demand kept in [0, {lim.pressure_ceiling / 1e3:.0f} kPa]"
    )
    return case


def with_jacobian(residuals):
    """``residuals`` whose JVP is J·v with J from :func:`linearise` (one solve carrying every sensitivity, as the
    engine's): a tangent optimistix can transpose (the fast solver's own tangents do not transpose, which
    Dogleg's gradient needs)."""

    @jax.custom_jvp
    def r(x):
        return residuals(x)

    @r.defjvp
    def _jvp(primals, tangents):
        value, jac = linearise(residuals, primals[0])
        return value, jac @ tangents[0]

    return lambda y, args: r(y)


def optimistix_solver(key):
    tol = cal.LM_TOLERANCE
    solver = optx.LevenbergMarquardt(tol, tol) if key.startswith("lm") else optx.Dogleg(tol, tol)
    return optx.BestSoFarLeastSquares(solver) if key.endswith("_best") else solver


def runner(case, key, max_steps):
    """A function () → (x, converged, steps, evaluations) running the solver ``key`` from the case's start."""
    if key == "engine":
        return lambda: case.engine(case.x0)
    solver = optimistix_solver(key)
    fn = (lambda y, args: case.residuals(y)) if key == "lm_linearize" else with_jacobian(case.residuals)

    @eqx.filter_jit
    def solve(y0):
        return optx.least_squares(fn, solver, y0, max_steps=max_steps, throw=False)

    def run():
        sol = solve(jnp.asarray(case.x0))
        x = np.asarray(sol.value)  # blocks until done
        steps = int(sol.stats["num_steps"])
        return x, bool(sol.result == optx.RESULTS.successful), steps, steps

    return run


def measure(case, keys, repeat, max_steps):
    runs = {SOLVERS[k]: runner(case, k, max_steps) for k in keys}
    names = list(runs)
    walls = {name: [] for name in names}
    outcome = {}
    for _ in range(1 + repeat):  # the first pass is cold; solvers alternate within each pass
        for name, run in runs.items():
            clock = time.perf_counter()
            outcome[name] = run()
            walls[name].append(time.perf_counter() - clock)
    lo, hi = case.bounds
    rows = {}
    for name in names:
        x, ok, steps, evaluations = outcome[name]
        rows[name] = {
            "first_s": walls[name][0],
            "warm_s": float(np.median(walls[name][1:])),
            "warm_all_s": walls[name][1:],
            "steps": steps,
            "evaluations": evaluations,
            "cost": case.cost(x),
            "converged": ok,
            "outside_box": int(np.sum((x < lo - 1e-12) | (x > hi + 1e-12))),
            "on_bound": int(np.sum((np.abs(x - lo) < 1e-9) | (np.abs(x - hi) < 1e-9))),
            "estimate": case.parameters(x),
        }
    engine = rows["engine"]
    x_engine = outcome["engine"][0]
    r_lin, jac = (np.asarray(a) for a in case.linearised(jnp.asarray(x_engine)))
    if case.statistical:  # Gauss–Newton's standard errors at the engine's point, the noise from its residuals
        variance = float(r_lin @ r_lin) / (r_lin.size - x_engine.size)
        se = np.sqrt(variance * np.diag(np.linalg.pinv(jac.T @ jac, hermitian=True)))
    for name in names[1:]:
        row = rows[name]
        if case.statistical:  # the largest move from the engine's point, in standard errors
            row["distance_se"] = float(np.max(np.abs(outcome[name][0] - x_engine) / se))
        row["warm_over_engine"] = row["warm_s"] / engine["warm_s"]
        row["cost_over_engine"] = row["cost"] / engine["cost"] - 1.0
        row["replaces_engine"] = bool(
            row["cost_over_engine"] <= SAME_COST
            and row["warm_over_engine"] <= WITHIN
            and row["outside_box"] == 0
            and row["converged"]
        )
    best = [n for n in names[1:] if rows[n]["replaces_engine"]]
    # The cost's own noise: at the engine's point, the solve carrying the sensitivities against the plain solve
    noise = abs(0.5 * float(r_lin @ r_lin) / engine["cost"] - 1.0)
    return {
        "description": case.description,
        "start": case.parameters(case.x0),
        "solvers": rows,
        "cost_noise_relative": noise,
        "verdict": f"switch to {min(best, key=lambda n: rows[n]['warm_s'])}" if best else "keep the engine",
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="warm runs per solver (after one cold run)")
    ap.add_argument("--max-steps", type=int, default=100, help="the engine's accepted steps, optimistix's steps")
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    ap.add_argument(
        "--solvers",
        default=",".join(DEFAULT_SOLVERS),
        help=f"comma-separated, of {', '.join(SOLVERS)}; the engine is always run first",
    )
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "least_squares.json"))
    args = ap.parse_args()
    cases = [c for c in args.cases.split(",") if c]
    keys = ["engine"] + [k for k in args.solvers.split(",") if k and k != "engine"]
    unknown = sorted(set(cases) - set(CASES)) + sorted(set(keys) - set(SOLVERS))
    if unknown or args.repeat < 1:
        ap.error(
            f"unknown case(s) or solver(s) {unknown}; cases: {', '.join(CASES)}; solvers: {', '.join(SOLVERS)}"
            if unknown
            else "--repeat must be at least 1"
        )
    make = {
        "fit_Y": lambda: fit_case("fit_Y", ["Y"], args.max_steps),
        "fit_Y_kp": lambda: fit_case("fit_Y_kp", ["Y", "pid.proportional"], args.max_steps),
        "profile": lambda: profile_case(args.max_steps),
    }
    out = {
        "environment": environment(),
        "data": str(_data.default_data_path()),
        "tolerance": cal.LM_TOLERANCE,
        "max_steps": args.max_steps,
        "repeat": args.repeat,
        "same_cost_relative": SAME_COST,
        "within_warm_ratio": WITHIN,
        "problems": {},
    }
    for label in cases:
        result = measure(make[label](), keys, args.repeat, args.max_steps)
        out["problems"][label] = result
        print(f"{label}: {result['description']}", flush=True)
        for name, row in result["solvers"].items():
            print(
                f"  {name:31s} warm {row['warm_s']:7.2f} s  first {row['first_s']:6.1f} s  steps {row['steps']:3d}  "
                f"evaluations {row['evaluations']:3d}  cost {row['cost']:.6g}  converged {row['converged']}  "
                f"outside box {row['outside_box']}"
                + (f"  {row['distance_se']:.2g} se from the engine's point" if "distance_se" in row else ""),
                flush=True,
            )
        print(f"  cost noise (relative) {result['cost_noise_relative']:.1e}; verdict: {result['verdict']}", flush=True)
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    print("wrote", path)


if __name__ == "__main__":
    main()
