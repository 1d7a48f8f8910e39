"""The public experiment's unrecorded pressure demand, estimated by the tracking filter from the measured length.

Run: ``python benchmarks/track_public.py [--data DIR] [--t-end 10]`` (the public MAMMOBOT experiment, read from
``../shared/data/mammobot`` beside the checkout or ``--data``; never copied into the repository).

The model is the command line's ``growjax track mammobot --sensors length --estimate-demand --discrepancy-size
2.2e-3,0.2``: the length the only sensor (0.2 mm), Y a random walk, the default tolerance budget, the length
discrepancy a fit found (Matérn-3/2, 2.2 mm, 0.2 s), the demand a random walk (3e5 Pa/√s). Both the causal
(filtered) and the whole-record (smoothed) estimates are compared with the published 0/150 kPa pulse train the
published model drives: the share of samples whose 90 % band holds the pulse train, the RMSE, and the same away
from the pulses' edges (an estimated demand cannot jump). Writes ``benchmarks/results/track_public.json`` and the
figure ``benchmarks/results/track_public.png`` (the smoothed demand, its band and the pulse train).
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import argparse
import json
import time
from pathlib import Path

import jax
import numpy as np

import growjax as gj
from growjax import track as tk
from growjax.data import experiment as ex
from growjax.track.figure import track_figure

HERE = Path(__file__).resolve().parent
from _environment import environment  # the script's folder is on the path

DISCREPANCY = (2.2e-3, 0.2)  # amplitude m, time scale s: what a fit of the public experiment found
EDGE_S = 0.15  # samples this close to a pulse edge are left out of the "away from the edges" scores


def model_for(base):
    """The command line's model for an unrecorded demand: the length read, Y and the demand estimated."""
    return tk.state_space(
        base,
        sensors=tk.sensor_set("length"),
        estimate=("Y",),
        discrepancy=tk.Discrepancy(*DISCREPANCY),
        inputs=(tk.InputState("pressure_demand"),),
    )


def pulse_edges(times: np.ndarray, pulse: np.ndarray) -> np.ndarray:
    """(T,) whether each sample lies within ``EDGE_S`` of a jump of the pulse train."""
    jumps = times[1:][np.abs(np.diff(pulse)) > 0]
    if jumps.size == 0:
        return np.zeros(times.size, bool)
    return np.min(np.abs(times[:, None] - jumps[None, :]), axis=1) < EDGE_S


def demand_scores(result, pulse: np.ndarray, edges: np.ndarray) -> dict:
    """The estimated demand against the pulse train: coverage of the 90 % band and RMSE, all samples and away from
    the edges (Pa)."""
    est, lo, hi = result.band("pressure_demand_Pa")
    inside = (pulse >= lo) & (pulse <= hi)
    err = est - pulse
    away = ~edges
    return {
        "coverage_90": float(np.mean(inside)),
        "coverage_90_away_from_edges": float(np.mean(inside[away])),
        "rmse_Pa": float(np.sqrt(np.mean(err**2))),
        "rmse_away_from_edges_Pa": float(np.sqrt(np.mean(err[away] ** 2))),
        "band_width_median_Pa": float(np.median(hi - lo)),
        "on_mean_Pa": float(np.mean(est[away & (pulse > 0)])),
    }


def small(path: Path, colors: int = 64) -> None:
    """Rewrite the PNG at ``path`` with a palette of ``colors`` (a quarter of its size; the file is kept in the
    repository)."""
    from PIL import Image

    Image.open(path).convert("RGB").quantize(colors=colors).save(path, optimize=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="the public experiment's folder (default: the shared one)")
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--out", default=str(HERE / "results" / "track_public.json"))
    args = ap.parse_args()
    jax.config.update("jax_compilation_cache_dir", os.environ.get("GROWJAX_CACHE_DIR", str(HERE / ".jax_cache")))
    folder = Path(args.data) if args.data else ex.shared_experiment_dir()
    if folder is None:
        raise SystemExit("the public experiment was not found: pass --data DIR")
    exp = ex.read(Path(folder) / "experiment.csv", sparse=ex.MEASURED_COLUMNS).window(args.t_end)
    model = model_for(gj.reference("forward"))
    times = np.asarray(exp.time, float)
    pulse = np.asarray(jax.vmap(gj.published_pulse())(times), float)
    edges = pulse_edges(times, pulse)
    res = {"environment": environment(), "t_end_s": float(times[-1]), "samples": int(times.size)}
    res["model"] = {"sensors": ["length"], "estimate": ["Y"], "discrepancy": list(DISCREPANCY), "edge_s": EDGE_S}
    results = {}
    for kind, smooth in (("filtered", False), ("smoothed", True)):
        clock = time.perf_counter()
        results[kind] = tk.track(exp, model, smooth=smooth)
        res[kind] = {**demand_scores(results[kind], pulse, edges), "wall_s": time.perf_counter() - clock}
        res[kind]["length"] = results[kind].score(np.asarray(exp["robot_length_m"]))
        print(
            f"{kind:9s}: pulse inside the 90 % band {res[kind]['coverage_90']:.2f} "
            f"({res[kind]['coverage_90_away_from_edges']:.2f} away from edges); RMSE "
            f"{1e-3 * res[kind]['rmse_Pa']:.1f} kPa ({1e-3 * res[kind]['rmse_away_from_edges_Pa']:.1f} away); "
            f"mean on the pulses {1e-3 * res[kind]['on_mean_Pa']:.0f} kPa; band {1e-3 * res[kind]['band_width_median_Pa']:.0f} kPa wide",
            flush=True,
        )
    est, lo, hi = results["smoothed"].band("pressure_demand_Pa")
    step = max(1, times.size // 500)  # the series every 20 ms: enough to redraw the figure
    res["series"] = {
        "time_s": times[::step].tolist(),
        "demand_Pa": est[::step].tolist(),
        "demand_lower_Pa": lo[::step].tolist(),
        "demand_upper_Pa": hi[::step].tolist(),
        "published_pulse_Pa": pulse[::step].tolist(),
    }
    out = Path(args.out)
    figure = out.with_suffix(".png")
    track_figure(
        results["smoothed"],
        figure,
        measured={"robot_length_m": np.asarray(exp["robot_length_m"])},
        compare=("published pulse train", times, pulse),
        title="public experiment: the demand estimated from the length (smoothed)",
    )
    small(figure)
    res["figure"] = str(figure.relative_to(HERE.parent)) if figure.is_relative_to(HERE.parent) else str(figure)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1) + "\n")
    print("wrote", out, "and", figure)


if __name__ == "__main__":
    main()
