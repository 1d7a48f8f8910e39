"""Benchmark of the 500-set Latin-hypercube sweep (issue 3), as same-process ratios.

Run: ``python benchmarks/sweep.py [--out benchmarks/results/sweep.json] [--quick]``.

1. the 500-set sweep of the 10 s forward model (quasi-static configuration) in one call: wall after
   compilation, compile time, and compile time in a second process with the persistent cache;
2. the same 500 sets as a Python loop over the single jitted simulation;
3. a SciPy baseline: the same quasi-static equations as a NumPy vector field (reverse flow through the
   bypass as a stiff flow, as one would write it) solved by ``solve_ivp(method="LSODA")`` per set, on a
   subset, scaled to 500;
4. sweep time for N = 100, 500, 2000, 10000 (chunked) and the process's peak memory;
5. the reference configuration (full model, diffrax Kvaerno5, rtol 1e-4) on a subset, scaled to 500, and
   the agreement of the quasi-static model with it (length difference, RMSE difference).
Every CPU core is exposed as a JAX device (``jax_num_cpu_devices``), so the sweep shards across them.
"""

from __future__ import annotations

import os

import jax

jax.config.update("jax_num_cpu_devices", int(os.environ.get("GROWJAX_CPU_DEVICES", os.cpu_count() or 1)))

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import growjax as gj
from growjax import experiment as ex
from growjax import sweep as sw
from growjax.metrics import length_rmse

REPO = Path(__file__).resolve().parents[1]
P_ATM = 101325.0


def numpy_field(params, demand, catheter):
    """The quasi-static equations as a NumPy right-hand side (the baseline a researcher would write)."""
    fl, pump, tube, tank, robot, pid = params.fluid, params.pump, params.tube, params.tank, params.robot, params.pid
    cv, dv = params.check_valve, params.valve
    rho, nu, el, alpha, npoly = (float(fl.density), float(fl.kinematic_viscosity), float(fl.bulk_modulus_liquid),
                                 float(fl.air_fraction), float(fl.polytropic_index))
    n, a_s = pump.n_syringes, float(pump.syringe_area)
    d, lt, kp, tau = float(tube.hydraulic_diameter), float(tube.length), float(tube.diameter_compliance), float(tube.wall_time_constant)
    r_hose = 2 * 64 * nu * rho * 0.5 * (lt + float(tube.length_additional)) / (2 * d * d * float(tube.area))
    b = float(pump.screw_damping) + n * a_s * a_s * r_hose
    a_r = float(robot.area)
    y_p, crack = float(robot.yield_pressure), float(robot.yield_pressure)
    k_gain = 2 * np.pi * float(robot.inner_radius) * float(robot.catheter_friction) / a_r
    kp_, ki_, kd_, nf = float(pid.proportional), float(pid.integral), float(pid.derivative), float(pid.filter_coefficient)
    gain_cv = (float(cv.area_max) - float(cv.leak_area)) / (float(cv.max_open_pressure) - crack)
    v_tank = float(tank.volume)

    def e_mix(p):
        pabs = max(P_ATM + p, 0.05 * P_ATM)
        return el * (1 + alpha * (P_ATM / pabs) ** (1 / npoly)) / (1 + alpha * el * P_ATM ** (1 / npoly) / (npoly * pabs ** ((npoly + 1) / npoly)))

    def orifice(area, dp, p_avg):
        p_cr = max(p_avg + P_ATM, 0.05 * P_ATM) * (1 - 0.999)
        return 0.7 * area * np.sqrt(2 / rho) * dp / (dp * dp + p_cr * p_cr) ** 0.25

    def ramp(x, w):
        return 0.0 if x <= 0 else (x * x / (2 * w) if x < w else x - w / 2)

    def step(x, w):
        s = min(max(x / w, 0.0), 1.0)
        return s * s * (3 - 2 * s)

    def rhs(t, y):
        p, x_p, wall, z_i, z_d, _xi = y
        err = demand(t) - p
        u = kp_ * err + ki_ * z_i + kd_ * nf * (err - z_d)
        push = n * a_s * (u - p)
        v_p = push / b if push >= 0 else push / (b + n * float(pump.penetration_coefficient) * max(-x_p, 0.0))
        p_r = y_p - k_gain * max(catheter(t), 0.0) * p
        dp = p - p_r
        area = min(float(cv.leak_area) + gain_cv * ramp(dp - crack, 50.0), float(cv.area_max))
        bypass = float(dv.leak_area) + (float(dv.area_max) - float(dv.leak_area)) * (1 - step(dp + 10.0, 10.0))
        q_r = orifice(area, dp, p - dp / 2) + orifice(bypass, dp, p - dp / 2)
        e = e_mix(p)
        d_wall = (kp * p - wall) / tau
        wall_flow = n * np.pi * (d + wall) / 2 * lt * (1 + p / e) * d_wall
        volume = n * np.pi * (d + wall) ** 2 / 4 * lt + v_tank
        return [(n * a_s * v_p - q_r - wall_flow) * e / volume, v_p, d_wall, err, nf * (err - z_d), q_r / a_r]

    return rhs


def scipy_run(params, inputs, exp, t1):
    demand = lambda t: float(inputs.pressure_demand(t))
    tc, lc = np.asarray(exp.time), np.asarray(exp["catheter_length_m"])
    catheter = lambda t: float(np.interp(t, tc, lc))
    y0 = np.asarray(gj.quasistatic.initial_state(params, inputs, gj.QuasiStaticConfig(t1=t1))) * np.asarray(gj.quasistatic.SCALES)
    grid = gj.QuasiStaticConfig(t1=t1).save_grid()
    sol = solve_ivp(numpy_field(params, demand, catheter), (grid[0], grid[-1]), y0, method="LSODA", t_eval=grid,
                    rtol=1e-6, atol=[1.0, 1e-9, 1e-13, 1e-2, 1.0, 1e-9], max_step=0.01)
    return sol.t, float(params.robot.initial_length) + sol.y[5], sol.status


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "sweep.json"))
    parser.add_argument("--quick", action="store_true", help="smaller loop/scaling/baseline subsets")
    args = parser.parse_args()
    folder = ex.shared_experiment_dir()
    exp = ex.read(folder / "experiment.csv") if folder else ex.read(REPO / "data" / "synthetic_forward.csv")
    base = gj.reference()
    cfg = gj.QuasiStaticConfig()
    inputs = ex.to_inputs(exp, "forward", base, cfg.t0, cfg.t1)
    measured = (exp.time, exp["robot_length_m"])
    names = [d.name for d in sw.paper_box()]
    values = sw.latin_hypercube(sw.paper_box(), 500, seed=0)
    out = {"data": exp.source, "devices": [str(d) for d in jax.devices()], "cpu_count": os.cpu_count()}

    # 1. one call
    res = sw.evaluate(values, names, base, inputs, cfg, measured=measured)
    again = sw.evaluate(values, names, base, inputs, cfg, measured=measured)
    out["sweep_500"] = {"wall_s": min(res.wall_s, again.wall_s), "compile_s": res.compile_s, "best": res.best(),
                        "n_failed": int(res.failed.sum()), "n_devices": res.n_devices}
    with tempfile.TemporaryDirectory() as cache:
        code = ("import jax, os; jax.config.update('jax_num_cpu_devices', os.cpu_count() or 1);"
                f"jax.config.update('jax_compilation_cache_dir', {cache!r});"
                "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0.5);"
                "import growjax as gj, json; from growjax import experiment as ex, sweep as sw;"
                f"exp = ex.read({exp.source!r}); b = gj.reference(); i = ex.to_inputs(exp, 'forward', b);"
                "r = sw.lhs_sweep(500, b, i, measured=(exp.time, exp['robot_length_m']));"
                "print(json.dumps(r.compile_s))")
        runs = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()[-1])
                for _ in range(2)]
    out["sweep_500"]["compile_s_cold_process"] = runs[0]
    out["sweep_500"]["compile_s_second_process_cached"] = runs[1]
    wall = out["sweep_500"]["wall_s"]

    # 2. Python loop over the single jitted simulation
    single = jax.jit(lambda theta: length_rmse(gj.simulate(gj.replace(base, **dict(zip(names, theta))), inputs, cfg),
                                               *measured, cfg.t0, cfg.t1))
    jax.block_until_ready(single(values[0]))
    n_loop = 100 if args.quick else 500
    start = time.perf_counter()
    loop_rmse = [float(single(v)) for v in values[:n_loop]]
    loop_s = (time.perf_counter() - start) * 500 / n_loop
    out["python_loop"] = {"sets_timed": n_loop, "wall_s_for_500": loop_s, "ratio_to_sweep": loop_s / wall,
                          "max_abs_rmse_difference_m": float(np.max(np.abs(np.asarray(loop_rmse) - res.rmse[:n_loop])))}

    # 3. SciPy baseline
    n_scipy = 2 if args.quick else 4
    start = time.perf_counter()
    diffs = []
    for v in values[:n_scipy]:
        p = gj.replace(base, **dict(zip(names, v)))
        t, length, _status = scipy_run(p, inputs, exp, cfg.t1)
        fast = gj.simulate(p, inputs, cfg)
        diffs.append(float(np.max(np.abs(length - np.asarray(fast.length))[t > 0.05])))
    scipy_s = (time.perf_counter() - start) * 500 / n_scipy  # includes 4 jitted QS runs (< 0.5 s)
    out["scipy_baseline"] = {"sets_timed": n_scipy, "method": "LSODA", "wall_s_for_500": scipy_s,
                             "ratio_to_sweep": scipy_s / wall, "max_abs_length_difference_m": max(diffs)}

    # 4. scaling and memory
    scaling = []
    for n in ([100, 500, 2000] if args.quick else [100, 500, 2000, 10000]):
        vals = sw.latin_hypercube(sw.paper_box(), n, seed=1)
        r = sw.evaluate(vals, names, base, inputs, cfg, measured=measured, chunk_size=2000, progress=n > 2000)
        scaling.append({"n": n, "wall_s": r.wall_s, "compile_s": r.compile_s, "per_set_ms": 1e3 * r.wall_s / n,
                        "peak_rss_mb": peak_rss_mb()})
    out["scaling"] = scaling

    # 5. reference configuration and agreement
    ref_cfg = gj.Config(rtol=1e-4, atol=1e-4)
    ts = cfg.save_grid()
    n_ref = 2 if args.quick else 4
    agree = []
    start_compile = time.perf_counter()
    jax.block_until_ready(gj.simulate(base, inputs, ref_cfg, ts=ts))
    ref_compile = time.perf_counter() - start_compile
    start = time.perf_counter()
    for v in values[:n_ref]:
        p = gj.replace(base, **dict(zip(names, v)))
        ref = gj.simulate(p, inputs, ref_cfg, ts=ts)
        fast = gj.simulate(p, inputs, cfg)
        late = ts > 0.05
        agree.append({"Y_Pa": float(v[1]),
                      "max_abs_length_difference_m": float(np.nanmax(np.abs(np.asarray(ref.length - fast.length))[late])),
                      "rmse_reference_m": float(length_rmse(ref, *measured, cfg.t0, cfg.t1)),
                      "rmse_quasistatic_m": float(length_rmse(fast, *measured, cfg.t0, cfg.t1))})
    ref_s = (time.perf_counter() - start) * 500 / n_ref
    out["reference_configuration"] = {"sets_timed": n_ref, "wall_s_for_500_loop": ref_s, "compile_s": ref_compile,
                                      "ratio_to_quasistatic_sweep": ref_s / wall, "agreement": agree}
    out["ratios"] = {"scipy_over_sweep": scipy_s / wall, "loop_over_sweep": loop_s / wall}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
