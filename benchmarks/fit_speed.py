"""The fit's cost under the discrepancy likelihood against the independent-noise likelihood, in one process.

Run: ``python benchmarks/fit_speed.py [--out benchmarks/results/fit_speed.json]``.

On the shipped synthetic experiment and (where present) the public one, 0–10 s, free Y, the default starts:
``growjax.calibration.fit`` with ``discrepancy="none", tolerances={}`` (independent noise, as the fit was) and with the
defaults (Matérn-3/2 discrepancy, the default tolerance budget, the rig inferred), and with the rig fixed and its
tolerances propagated (``rig="fixed"``), and with the rig's secants instead of its tangents
(``rig_tangents=False``), relinearised and linearised once at nominal (``relinearise=False``), each run
``--repeat`` times (they alternate, so a drift of the machine's speed falls on all alike); the first run of each
compiles. Printed: the median warm wall time of each, the default's ratio to independent noise (target ≤ 1.5), to
the fixed rig, to the relinearised secants and to the once-linearised secants, and the first runs. The results file
is written after each data set.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax.data import datasets as _data
from growjax.data import experiment as ex
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "fit_speed.json"))
    args = ap.parse_args()
    sources = {"shipped synthetic": _data.default_data_path()}
    public = ex.shared_experiment_dir()
    if public is not None:
        sources["public experiment"] = public / "experiment.csv"
    out = {}
    for label, path in sources.items():
        exp = ex.read(path).window(10.0 + 1e-9)
        base, config = gj.reference("forward"), gj.Config(t1=10.0)
        inputs = ex.to_inputs(exp, "forward", base, config.t0, config.t1)
        one = xs.ExperimentSet.single(exp, defaults=base, inputs=inputs, sensors=["length"])
        kinds = {
            "independent": {"likelihood": cal.Likelihood(discrepancy="none", tolerances={})},
            "discrepancy": {},
            "rig_fixed": {"likelihood": cal.Likelihood(rig="fixed")},
            "secants": {"rig_tangents": False},
            "once": {"rig_tangents": False, "relinearise": False},
        }
        walls, lins = {kind: [] for kind in kinds}, {}
        for _ in range(args.repeat):  # interleaved: a drift of the machine's speed falls on both alike
            for kind, options in kinds.items():
                clock = time.perf_counter()
                res = cal.fit(one, ["Y"], config=config, **options)
                walls[kind].append(time.perf_counter() - clock)
                lins[kind] = res.linearisations
        row = {
            kind: {"first_s": w[0], "warm_s": float(np.median(w[1:])), "linearisations": lins[kind]}
            for kind, w in walls.items()
        }
        row["ratio_warm"] = row["discrepancy"]["warm_s"] / row["independent"]["warm_s"]
        row["ratio_first"] = row["discrepancy"]["first_s"] / row["independent"]["first_s"]
        row["ratio_warm_inferred_over_fixed"] = row["discrepancy"]["warm_s"] / row["rig_fixed"]["warm_s"]
        row["ratio_warm_over_once"] = row["discrepancy"]["warm_s"] / row["once"]["warm_s"]
        row["ratio_warm_over_secants"] = row["discrepancy"]["warm_s"] / row["secants"]["warm_s"]
        out[label] = row
        print(
            f"{label}: independent {row['independent']['warm_s']:.2f} s, discrepancy "
            f"{row['discrepancy']['warm_s']:.2f} s warm (ratio {row['ratio_warm']:.2f}); first runs "
            f"{row['independent']['first_s']:.1f} / {row['discrepancy']['first_s']:.1f} s; the rig fixed "
            f"{row['rig_fixed']['warm_s']:.2f} s warm (inferred over fixed "
            f"{row['ratio_warm_inferred_over_fixed']:.2f}); "
            f"secants relinearised {row['secants']['warm_s']:.2f} s ({row['secants']['linearisations']} "
            f"linearisations), linearised once {row['once']['warm_s']:.2f} s",
            flush=True,
        )
        path = Path(args.out)  # written after each data set: a run cut short keeps those done
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"environment": environment(), **out}, indent=1))


if __name__ == "__main__":
    main()
