"""The tracking filter against a JAX filtering library's on the same model: dynamax's extended Kalman filter (and
its iterated form) over growjax's state-space model, on one reference-made record of the tracking benchmark.

Run: ``python benchmarks/track_libraries.py [--record benchmarks/results/track_data/rig0.csv]``, with dynamax
importable (not a dependency of growjax: ``pip install dynamax`` brings tfp-nightly, optax and fastprogress; the
run needs only its filter). Writes ``benchmarks/results/track_libraries.json`` and prints a table.

Both run the same transition (``growjax.track.StateSpace.advance``, the fast configuration's solver) and the same
sensors, whitened by their noise. dynamax's filter is one ``lax.scan`` over the record with constant process noise
and no missing readings (its model is discrete-time); growjax's is the compiled step called per sample.
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import track as tk
from growjax.data import experiment as ex
from growjax.track.sensors import measurements

HERE = Path(__file__).resolve().parent
from _environment import environment  # the script's folder is on the path
from _track_data import read_record


def dynamax_run(model, exp, iterations: int) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(filtered means (T, N), covariances (T, N, N), first call s, second call s) of dynamax's extended filter."""
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, extended_kalman_filter

    times = np.asarray(exp.time, float)
    inputs = ex.to_inputs(exp, "forward", model.params, model.config.t0, float(times[-1]) + 0.01)
    breaks = model.breaks(inputs, model.config.t0, float(times[-1]) + 0.01)
    sd = model.noise_sd()
    readings = measurements(exp, model.sensors) / np.asarray(sd)
    m0, p0 = model.initial()
    m1, jac, _ = jax.jit(lambda m: model.linearised_advance(m, inputs, model.config.t0, times[0], breaks))(m0)
    p1 = jac @ p0 @ jac.T + model.process_noise(times[0] - model.config.t0)
    dt = float(np.median(np.diff(times)))
    params = ParamsNLGSSM(
        initial_mean=m1,
        initial_covariance=p1,
        dynamics_function=lambda z, u: model.advance(z, inputs, u[0], u[1], breaks)[0],
        dynamics_covariance=model.process_noise(dt) + 1e-18 * jnp.eye(model.size),
        emission_function=lambda z, u: model.measure(z, u[0], inputs) / sd,
        emission_covariance=jnp.eye(len(model.sensors)),
    )
    windows = jnp.stack([times, np.append(times[1:], times[-1] + dt)], axis=1)
    run = jax.jit(lambda y, u: extended_kalman_filter(params, y, u, num_iter=iterations))
    clock = time.perf_counter()
    post = jax.block_until_ready(run(jnp.asarray(readings), windows))
    first = time.perf_counter() - clock
    clock = time.perf_counter()
    post = jax.block_until_ready(run(jnp.asarray(readings), windows))
    second = time.perf_counter() - clock
    return np.asarray(post.filtered_means), np.asarray(post.filtered_covariances), first, second


def length_score(model, exp, means, covs, truth) -> dict:
    """The length's RMSE and 90 % band coverage of filtered beliefs."""
    from growjax.track.filter import compiled
    from growjax.track.result import report

    inputs = ex.to_inputs(exp, "forward", model.params, model.config.t0, float(exp.time[-1]))
    mids, sds = compiled(model, tk.ExtendedKalman()).linearised(exp.time, means, covs, inputs)
    cols = report(model, mids, sds)
    est, lo, hi = cols["robot_length_m"], cols["robot_length_lower_m"], cols["robot_length_upper_m"]
    return {
        "rmse_m": float(np.sqrt(np.mean((est - truth) ** 2))),
        "coverage_90": float(np.mean((truth >= lo) & (truth <= hi))),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", default=str(HERE / "results" / "track_data" / "rig0.csv"))
    ap.add_argument("--out", default=str(HERE / "results" / "track_libraries.json"))
    args = ap.parse_args()
    jax.config.update("jax_compilation_cache_dir", os.environ.get("GROWJAX_CACHE_DIR", str(HERE / ".jax_cache")))
    exp, meta = read_record(Path(args.record))
    truth = np.asarray(meta["noise_free_length_m"], float)
    model = tk.state_space(gj.reference("forward"), sensors=tk.sensor_set("pressure,syringe"), estimate=("Y",))
    res = {"environment": environment(), "record": args.record, "samples": int(exp.time.size), "rows": {}}
    clock = time.perf_counter()
    tk.track(exp, model)
    first = time.perf_counter() - clock
    clock = time.perf_counter()
    mine = tk.track(exp, model)
    second = time.perf_counter() - clock
    res["rows"]["growjax extended Kalman"] = {**mine.score(truth), "first_s": first, "record_s": second}
    import dynamax

    res["dynamax"] = getattr(dynamax, "__version__", "")
    for name, iterations in (("dynamax extended Kalman", 1), ("dynamax iterated extended Kalman (2)", 2)):
        means, covs, first, second = dynamax_run(model, exp, iterations)
        res["rows"][name] = {**length_score(model, exp, means, covs, truth), "first_s": first, "record_s": second}
    Path(args.out).write_text(json.dumps(res, indent=1) + "\n")
    print("| filter | length RMSE (mm) | 90 % band covers | first call (s) | record, compiled (s) |")
    print("|---|---|---|---|---|")
    for name, r in res["rows"].items():
        print(
            f"| {name} | {1e3 * r['rmse_m']:.3f} | {r['coverage_90']:.2f} | {r['first_s']:.1f} | {r['record_s']:.2f} |"
        )


if __name__ == "__main__":
    main()
