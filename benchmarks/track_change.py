"""Change detection and output feedback, measured against their targets.

Run: ``python benchmarks/track_change.py [--seeds 10] [--clean 10] [--feedback 10] [--data DIR]`` (a first run makes
the reference records, ``_track_data.py``; later runs read them back from ``--data``, default
``benchmarks/results/track_data``). ``--seeds 0``, ``--clean 0`` or ``--feedback 0`` skips a study.

* **Change detection** (``growjax.track.watch``, the command line's default model: pressure and syringe, Y a random
  walk, the default tolerance budget): on 10 s records made by the reference configuration on drawn rigs, a leak
  (2e-13 m³/(s·Pa)) opening or a tip load (0.3 N) appearing at a time drawn in 2–8 s: flagged within 0.5 s of the
  change (target ≥ 9 of 10 seeds) and named right (target ≥ 8 of 10); on 60 s clean records: no flag (target
  none in 10).
* **Output feedback** (``growjax.control.run_on_estimate`` with ``growjax.track.Filter``): the length PID, its
  feed-forward profile optimised and its gains tuned on the fast configuration for the shipped target (the public
  experiment's length where it is here, else the shipped synthetic one), acting on the filter's estimate from the
  pressure and syringe (0.5 kPa, 5 µm) on the reference configuration of drawn rigs: length RMSE (target ≤ 1 mm)
  and the membrane limit (never crossed), beside the same loop reading the true length.

Writes ``benchmarks/results/track_change.json`` with the machine and versions, and prints a table.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import control as gc
from growjax import track as tk
from growjax.calibration import tolerance as tl
from growjax.data import experiment as ex
from growjax.data.datasets import default_data_path
from growjax.model.limits import limits

HERE = Path(__file__).resolve().parent
from _environment import environment  # the script's folder is on the path
from _track_data import drift_base, make_change_records, make_clean_records, read_record

FLAG_WITHIN_S = 0.5
NAMES = {"leak": "leak", "tip": "tip load"}


def model_for(base):
    return tk.state_space(base, sensors=tk.sensor_set("pressure,syringe"), estimate=("Y",))


def watch_record(path: Path, kind: str | None, base=None) -> dict:
    """One record watched by the filter on ``base`` (default the reference rig): its flags, and for a change record
    (``kind``) whether the first flag after the change came within `FLAG_WITHIN_S` and named it right."""
    exp, meta = read_record(path)
    clock = time.perf_counter()
    try:
        watched = tk.watch(exp, model_for(gj.reference("forward") if base is None else base))
    except RuntimeError as err:  # the filter diverged and the solver failed: the record counts as missed
        row = {"record": path.name, "failed": str(err), "changes": [], "dismissed": [], "max_statistic": float("nan")}
        if kind is not None:
            at = meta["switch"]["at_s"]
            row.update(at_s=at, false_before=0, delay_s=None, flagged=False, named_right=False)
        return row
    row = {"record": path.name, "changes": watched.summary(), "wall_s": time.perf_counter() - clock}
    row["dismissed"] = [c.as_dict() for c in watched.dismissed]
    row["max_statistic"] = float(watched.statistic.max())
    if kind is not None:
        at = meta["switch"]["at_s"]
        first = next((c for c in watched.changes if c.flagged_s >= at), None)
        early = [c for c in watched.changes if c.flagged_s < at]
        row.update(at_s=at, false_before=len(early))
        row["delay_s"] = None if first is None else first.flagged_s - at
        row["flagged"] = first is not None and first.flagged_s - at <= FLAG_WITHIN_S
        row["named_right"] = first is not None and first.effect == NAMES[kind]
    return row


def change_study(folder: Path, seeds: int, clean: int, log) -> dict:
    res: dict = {}
    for kind in ("leak", "tip") if seeds else ():
        rows = [watch_record(p, kind) for p in make_change_records(folder, kind, seeds, 10.0, log)]
        for r in rows:
            log(f"  {r['record']}: at {r['at_s']:.2f} s, delay {r['delay_s']}, named {r['named_right']}")
        res[kind] = {
            "flagged_within_0.5_s": sum(r["flagged"] for r in rows),
            "named_right": sum(r["named_right"] for r in rows),
            "false_flags_before": sum(r["false_before"] for r in rows),
            "seeds": len(rows),
            "failed": [r["record"] for r in rows if "failed" in r],
            "delay_s_median": float(np.median([r["delay_s"] for r in rows if r["delay_s"] is not None] or [np.nan])),
            "rows": rows,
        }
    if clean:
        # on the long robot the clean records were made with (its stroke beyond a minute's growth)
        rows = [watch_record(p, None, drift_base({})) for p in make_clean_records(folder, clean, 60.0, log)]
        res["clean"] = {
            "records_flagged": sum(bool(r["changes"]) for r in rows),
            "records_with_dismissed_flags": sum(bool(r.get("dismissed")) for r in rows),
            "records": len(rows),
            "failed": [r["record"] for r in rows if "failed" in r],
            "max_statistic": max(r["max_statistic"] for r in rows if "failed" not in r),
            "threshold": tk.Cusum().threshold,
            "rows": rows,
        }
    return res


def designed_pid(target, t_end: float, log):
    """The length PID of the control benchmark: the feed-forward profile optimised and the gains tuned on the fast
    configuration at the nominal rig."""
    p = gc.plant_params("forward", target)
    lim = limits(p)
    prof = gc.optimize_profile(p, target, t_end, knot_dt=0.2, iterations=20, lim=lim)
    pid0 = gc.LengthPID(jnp.asarray(gc.DEFAULT_LOG_GAINS), jnp.asarray(prof.knots), jnp.asarray(prof.demand))
    cost = gc.pid_cost_fn(p, target, t_end, pid0, None, lim)
    tuned = gc.tune_pid(cost, pid0.log_gains, iterations=20)
    log(f"PID designed: gains {tuned.gains}")
    return eqx.tree_at(lambda c: c.log_gains, pid0, jnp.asarray(tuned.log_gains)), p, lim


def feedback_study(n: int, t_end: float, log) -> dict:
    folder = ex.shared_experiment_dir()
    data = folder / "experiment.csv" if folder else default_data_path()
    target = gc.target_from_experiment(ex.read(data), t_end)
    pid, nominal, lim = designed_pid(target, t_end, log)
    draws = tl.rig_draws(n, nominal, tl.default_budget(nominal), seed=20261202)
    estimator = tk.Filter(model_for(nominal))
    rows = []
    for i in range(n):
        rig = gj.replace(nominal, **{k: float(v[i]) for k, v in draws.items()})
        plant = gc.Plant.make(rig, gj.Config(fidelity="reference", t1=t_end))
        clock = time.perf_counter()
        try:
            est = gc.run_on_estimate(plant, pid, target, t_end, estimator, seed=i, lim=lim)
        except RuntimeError as err:  # the estimator diverged: the rig counts as missed
            rows.append({"rig": i, "failed": str(err)})
            log(f"  rig {i}: failed: {err}")
            continue
        wall = time.perf_counter() - clock
        measured = gc.run_closed_loop(plant, pid, target, t_end, lim)
        err = est.estimate - est.result.length
        rows.append(
            {
                "rig": i,
                "rmse_m": est.result.rmse_m,
                "limit_crossed": est.result.pressure_limit_crossed,
                "peak_pressure_Pa": float(np.nanmax(est.result.pressure)),
                "estimate_rmse_m": float(np.sqrt(np.mean(err**2))),
                "estimate_coverage_90": float(np.mean(np.abs(err) <= 1.6448536 * est.sd)),
                "measured_length_rmse_m": measured.rmse_m,
                "estimator_step_ms_median": 1e3 * float(np.median(est.step_s[1:])),
                "wall_s": wall,
            }
        )
        log(f"  rig {i}: RMSE {1e3 * est.result.rmse_m:.3f} mm (length read: {1e3 * measured.rmse_m:.3f} mm)")
    done = [r for r in rows if "failed" not in r]
    return {
        "data": str(data),
        "t_end_s": t_end,
        "failed": [r["rig"] for r in rows if "failed" in r],
        "rmse_m_max": max(r["rmse_m"] for r in done) if done else None,
        "rmse_m_median": float(np.median([r["rmse_m"] for r in done])) if done else None,
        "limit_crossed": any(r["limit_crossed"] for r in done),
        "rows": rows,
    }


def table(res: dict) -> list[str]:
    lines = []
    for kind in ("leak", "tip"):
        if kind in res.get("change", {}):
            r = res["change"][kind]
            lines.append(
                f"{kind:5s}: flagged within 0.5 s {r['flagged_within_0.5_s']}/{r['seeds']} (target ≥ 9), named right "
                f"{r['named_right']}/{r['seeds']} (≥ 8), median delay {r['delay_s_median']:.2f} s"
            )
    if "clean" in res.get("change", {}):
        r = res["change"]["clean"]
        lines.append(
            f"clean: {r['records_flagged']}/{r['records']} 60 s records flagged (target 0); largest statistic "
            f"{r['max_statistic']:.1f} (threshold {r['threshold']:g}); "
            f"{r.get('records_with_dismissed_flags', 0)} with a flag dismissed as too small"
        )
    if "feedback" in res:
        r = res["feedback"]
        lines.append(
            f"output feedback, {len(r['rows'])} rigs, reference plant: length RMSE median "
            f"{1e3 * r['rmse_m_median']:.3f} mm, worst {1e3 * r['rmse_m_max']:.3f} mm (target ≤ 1), "
            f"membrane limit crossed: {r['limit_crossed']}"
        )
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="leak and tip records each (0: none)")
    ap.add_argument("--clean", type=int, default=10, help="clean 60 s records (0: none)")
    ap.add_argument("--feedback", type=int, default=10, help="rigs of the output-feedback study (0: none)")
    ap.add_argument("--feedback-t-end", type=float, default=10.0)
    ap.add_argument("--data", default=str(HERE / "results" / "track_data"))
    ap.add_argument("--out", default=str(HERE / "results" / "track_change.json"))
    args = ap.parse_args()
    folder = Path(args.data)
    folder.mkdir(parents=True, exist_ok=True)
    log = lambda msg: print(msg, flush=True)  # noqa: E731
    res: dict = {"change": change_study(folder, args.seeds, args.clean, log)}
    if args.feedback:
        res["feedback"] = feedback_study(args.feedback, args.feedback_t_end, log)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"environment": environment(), **res}, indent=2, default=float) + "\n")
    print("\n".join(table(res)))
    print("wrote", out)


if __name__ == "__main__":
    main()
