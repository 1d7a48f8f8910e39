"""Tracking the robot from the pump's own sensors, measured against its targets.

Run: ``python benchmarks/track.py [--rigs 20] [--methods extended unscented] [--drift 10] [--walk Q] [--data DIR]``
(a first run makes the reference records, about a minute each after the reference configuration's compile; later
runs read them back from ``--data``, default ``benchmarks/results/track_data``).

On records made by the reference configuration (``_track_data.py``: rigs drawn from the default tolerance budget,
the published pulse, pressure noise 0.5 kPa, the syringe read to 5 µm), each filter reads the pressure and the
syringe displacement only, estimates Y as a random walk and carries the rig's tolerances as static states:

* length RMSE and the share of samples inside the 90 % band, per rig, over 10 s (targets: RMSE ≤ 0.5 mm, share
  0.80–0.97), the innovations' NIS per reading (1 when honest) and the NEES of the rig's errors at the end;
* the drift records (Y +10 % over 60 s): the same scores and the share of samples whose Y band covers the true Y;
* cost: the filter's step (median and 90th percentile, wall and CPU, after compiling) against ``simulate_from`` over
  the same 10 ms interval in the same process (target ≤ 1 ms, ≥ 10× real time on one core), and a 10 s record
  smoothed (target ≤ 5 s).

XLA runs single-threaded (``--xla_cpu_multi_thread_eigen=false``; the process may also be pinned to one core with
``taskset -c 0``). Writes ``benchmarks/results/track.json`` with the machine and versions, and prints a table.
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
from growjax.simulation.simulate import simulate_from

HERE = Path(__file__).resolve().parent
from _environment import environment  # the script's folder is on the path
from _track_data import drift_base, make_drift_records, make_rig_records, read_record

METHODS = {"extended": tk.ExtendedKalman(), "unscented": tk.Unscented()}
TARGETS = {"rmse_m": 5e-4, "coverage": (0.80, 0.97), "step_s": 1e-3, "smooth_s": 5.0}


def model_for(base, walk: float | None = None):
    """The filter's model: pressure and syringe, Y a random walk (``walk`` per √s; None: the package's default),
    the default tolerance budget."""
    walks = None if walk is None else {"Y": walk}
    return tk.state_space(base, sensors=tk.sensor_set("pressure,syringe"), estimate=("Y",), walk=walks)


def nees(model, result, rig: dict, base) -> float:
    """The NEES of the rig's toleranced parameters' relative errors at the last sample (χ² with q dof if honest)."""
    n = model.model_size
    idx = [i for i, p in enumerate(model.parameters) if p.tolerance]
    truth = np.array(
        [np.log(rig[model.parameters[i].name] / float(gj.get(base, model.parameters[i].name))) for i in idx]
    )
    err = result.mean[-1, n + np.array(idx)] - truth
    cov = result.cov[-1][np.ix_(n + np.array(idx), n + np.array(idx))]
    return float(err @ np.linalg.solve(cov, err))


def score_record(path: Path, model, method, base) -> dict:
    """One record tracked by one method: its scores and costs."""
    exp, meta = read_record(path)
    truth = np.asarray(meta["noise_free_length_m"], float)
    cpu = time.process_time()
    try:
        result = tk.track(exp, model, method=method)
    except RuntimeError as err:  # the filter diverged and the solver failed: a failure of the target, not the run
        return {"record": path.stem, "failed": str(err)}
    cpu = time.process_time() - cpu
    row = {"record": path.stem, **result.score(truth), **result.consistency()}
    row["nees_rig"] = nees(model, result, meta["rig"], base)
    row["step_wall_s"] = result.step_seconds[1:].tolist()
    row["cpu_s"] = cpu
    est, lo, hi = result.band("Y_Pa")
    y_true = np.asarray(meta.get("drift", {}).get("values", np.full(truth.size, float(gj.get(base, "Y")))), float)
    row["y_coverage_90"] = float(np.mean((y_true >= lo) & (y_true <= hi)))
    row["y_final_Pa"] = [float(est[-1]), float(lo[-1]), float(hi[-1]), float(y_true[-1])]
    return row


def baseline_step(model, path: Path, n: int = 300) -> dict:
    """``simulate_from`` over the record's first ``n`` 10 ms intervals (the model's configuration and nominal
    parameters, no filter): the wall time of each, s, after compiling."""
    exp, _ = read_record(path)
    inputs = ex.to_inputs(exp, "forward", model.params, model.config.t0, float(exp.time[-1]))
    breaks = model.breaks(inputs, model.config.t0, float(exp.time[-1]))
    y0 = model.initial()[0][: model.model_size]
    advance = jax.jit(
        lambda y, ta, tb: simulate_from(model.params, inputs, model.config, y, (ta, tb), tb[None], breaks).final_state
    )
    y = jax.block_until_ready(advance(y0, jnp.asarray(model.config.t0), jnp.asarray(exp.time[0])))
    seconds = []
    for ta, tb in zip(exp.time[: n - 1], exp.time[1:n]):
        clock = time.perf_counter()
        y = jax.block_until_ready(advance(y, jnp.asarray(ta), jnp.asarray(tb)))
        seconds.append(time.perf_counter() - clock)
    return {"step_wall_s": seconds}


def smooth_time(model, method, path: Path) -> float:
    """Wall time of a whole record tracked and smoothed, s (programs compiled)."""
    exp, _ = read_record(path)
    clock = time.perf_counter()
    tk.track(exp, model, method=method, smooth=True)
    return time.perf_counter() - clock


def summarise(rows: list[dict]) -> dict:
    """The scores over records: mean, worst, and the share meeting the targets; ``failed``: the records whose
    track failed (counted as missing every target)."""
    failed = [r["record"] for r in rows if "failed" in r]
    rows = [r for r in rows if "failed" not in r]
    if not rows:
        return {"records": len(failed), "failed": failed}
    rmse = np.array([r["rmse_m"] for r in rows])
    cov = np.array([r["coverage_90"] for r in rows])
    steps = np.concatenate([r["step_wall_s"] for r in rows])
    nis = np.array([r["nis_per_reading"] for r in rows])
    q = np.array([r["nees_rig"] for r in rows])
    return {
        "records": len(rows) + len(failed),
        "failed": failed,
        "rmse_mean_m": float(np.mean(rmse)),
        "rmse_worst_m": float(np.max(rmse)),
        "rmse_met": int(np.sum(rmse <= TARGETS["rmse_m"])),
        "coverage_mean": float(np.mean(cov)),
        "coverage_min": float(np.min(cov)),
        "coverage_max": float(np.max(cov)),
        "nis_per_reading_mean": float(np.mean(nis)),
        "nees_rig_mean": float(np.mean(q)),
        "y_coverage_mean": float(np.mean([r["y_coverage_90"] for r in rows])),
        "step_median_s": float(np.median(steps)),
        "step_p90_s": float(np.percentile(steps, 90)),
        "step_mean_s": float(np.mean(steps)),
        "cpu_per_step_s": float(sum(r["cpu_s"] for r in rows) / steps.size),
    }


def run_method(name, rigs, drifts, log, walk: float | None = None) -> dict:
    method = METHODS[name]
    base = gj.reference("forward")
    out = {"rigs": [], "drift": []}
    for path in rigs:
        out["rigs"].append(score_record(path, model_for(base, walk), method, base))
        r = out["rigs"][-1]
        if "failed" in r:
            log(f"{name:10s} {r['record']:7s} failed: {r['failed']}")
            continue
        log(
            f"{name:10s} {r['record']:7s} RMSE {1e3 * r['rmse_m']:.3f} mm  cover {r['coverage_90']:.2f}  NIS "
            f"{r['nis_per_reading']:.2f}  step {1e3 * np.median(r['step_wall_s']):.2f} ms"
        )
    for path in drifts:
        out["drift"].append(score_record(path, model_for(drift_base({}), walk), method, drift_base({})))
        r = out["drift"][-1]
        if "failed" in r:
            log(f"{name:10s} {r['record']:7s} failed: {r['failed']}")
            continue
        log(
            f"{name:10s} {r['record']:7s} RMSE {1e3 * r['rmse_m']:.3f} mm  cover {r['coverage_90']:.2f}  Y cover "
            f"{r['y_coverage_90']:.2f}  Y end {r['y_final_Pa']}"
        )
    out["summary"] = summarise(out["rigs"])
    out["drift_summary"] = summarise(out["drift"]) if out["drift"] else None
    if rigs:
        out["smooth_10s_s"] = smooth_time(model_for(base, walk), method, rigs[0])
    return out


def compact(res: dict) -> None:
    """Each record's step times (and the baseline's) replaced by their median and 90th percentile, s, in place."""
    rows = [res["baseline"]] + [r for m in res["methods"].values() for r in m["rigs"] + m["drift"]]
    for r in rows:
        if "step_wall_s" in r:
            steps = np.asarray(r.pop("step_wall_s"))
            r.update(steps=int(steps.size), step_median_s=float(np.median(steps)))
            r["step_p90_s"] = float(np.percentile(steps, 90))


def table(res: dict) -> list[str]:
    lines = [
        "| method | length RMSE mean / worst (mm) | rigs ≤ 0.5 mm | 90 % band covers (mean, min) | NIS per "
        "reading | NEES rig (dof 6) | step median / p90 (ms) | × real time | vs simulate_from | 10 s smoothed (s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    base = res["baseline"]["step_median_s"]
    for name, m in res["methods"].items():
        s = m["summary"]
        lines.append(
            f"| {name} | {1e3 * s['rmse_mean_m']:.3f} / {1e3 * s['rmse_worst_m']:.3f} | {s['rmse_met']} of "
            f"{s['records']} | {s['coverage_mean']:.2f}, {s['coverage_min']:.2f} | {s['nis_per_reading_mean']:.2f} | "
            f"{s['nees_rig_mean']:.1f} | {1e3 * s['step_median_s']:.2f} / {1e3 * s['step_p90_s']:.2f} | "
            f"{0.01 / s['step_median_s']:.0f} | {s['step_median_s'] / base:.1f}× | {m.get('smooth_10s_s', 0):.1f} |"
        )
    for name, m in res["methods"].items():
        d = m.get("drift_summary")
        if d and "rmse_mean_m" not in d:
            lines.append(f"| {name}, Y +10 % over 60 s | failed: {', '.join(d['failed'])} | | | | | | | | |")
        elif d:
            lines.append(
                f"| {name}, Y +10 % over 60 s | {1e3 * d['rmse_mean_m']:.3f} / {1e3 * d['rmse_worst_m']:.3f} | "
                f"{d['rmse_met']} of {d['records']} | {d['coverage_mean']:.2f}, {d['coverage_min']:.2f} "
                f"(Y band covers {d['y_coverage_mean']:.2f}) | {d['nis_per_reading_mean']:.2f} | "
                f"{d['nees_rig_mean']:.1f} | {1e3 * d['step_median_s']:.2f} / {1e3 * d['step_p90_s']:.2f} | | | |"
            )
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", type=int, default=20)
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--drift", type=int, default=10, help="drift records (60 s each; 0: none)")
    ap.add_argument("--drift-t-end", type=float, default=60.0)
    ap.add_argument("--methods", nargs="+", choices=sorted(METHODS), default=["extended", "unscented"])
    ap.add_argument("--data", default=str(HERE / "results" / "track_data"))
    ap.add_argument("--walk", type=float, default=None, help="Y's random walk per √s (default: the package's)")
    ap.add_argument("--data-only", action="store_true", help="make the records and stop")
    ap.add_argument("--out", default=str(HERE / "results" / "track.json"))
    args = ap.parse_args()
    jax.config.update("jax_compilation_cache_dir", os.environ.get("GROWJAX_CACHE_DIR", str(HERE / ".jax_cache")))
    log = lambda text: print(text, flush=True)  # noqa: E731
    clock = time.perf_counter()
    folder = Path(args.data)
    folder.mkdir(parents=True, exist_ok=True)
    rigs = make_rig_records(folder, args.rigs, args.t_end, log)
    drifts = make_drift_records(folder, args.drift, args.drift_t_end, log) if args.drift else []
    if args.data_only:
        return
    res = {"environment": environment(), "xla_flags": os.environ.get("XLA_FLAGS", ""), "targets": TARGETS}
    res["walk"] = args.walk
    res["baseline"] = baseline_step(model_for(gj.reference("forward"), args.walk), rigs[0])
    res["baseline"]["step_median_s"] = float(np.median(res["baseline"]["step_wall_s"]))
    res["methods"] = {name: run_method(name, rigs, drifts, log, args.walk) for name in args.methods}
    compact(res)
    res["load_average"] = os.getloadavg()
    res["wall_s"] = time.perf_counter() - clock
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(res, indent=1) + "\n")
    print("\n".join(table(res)))
    print(f"wrote {args.out} ({res['wall_s']:.0f} s; load average {res['load_average'][0]:.1f})")


if __name__ == "__main__":
    main()
