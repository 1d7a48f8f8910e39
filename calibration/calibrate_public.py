"""End-to-end calibration of the public MAMMOBOT experiment: fits, identifiability, NUTS posterior, figures.

Run from the repository root: ``python calibration/calibrate_public.py [--quick] [--out out/calibration]``.
``--quick`` samples 0–2 s with 2 chains × 100 + 100 draws (minutes). The default samples the full 0–10 s
with 4 × 500 + 500, which takes hours on a 2-core CPU with the present model (see README).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import growjax as gj
from growjax import experiment as ex
from growjax import fit as gf
from growjax import posterior as gpost
from growjax.plotting import trajectory_figure


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="out/calibration")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    folder = ex.shared_experiment_dir()
    if folder is None:
        raise SystemExit("the public experiment (../shared/data/mammobot) is not beside this checkout")
    exp = ex.read(folder / "experiment.csv")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = gj.reference()
    cfg = gj.QuasiStaticConfig()
    inputs = ex.to_inputs(exp, "forward", base, cfg.t0, cfg.t1)
    report = {}

    y_fit = gf.fit(exp.time, exp["robot_length_m"], inputs, free=["Y"], config=cfg)
    report["fit_Y"] = y_fit.summary()
    all_fit = gf.fit(exp.time, exp["robot_length_m"], inputs, free=["Y", "ext", "n"], config=cfg)
    report["fit_Y_ext_n"] = all_fit.summary()
    traj = gj.simulate(gj.replace(base, **y_fit.estimate), inputs, cfg)
    trajectory_figure(traj, out / "fit.png", measured=(exp.time, exp["robot_length_m"]),
                      title=f"fitted Y = {y_fit.estimate['robot.yield_pressure']:.0f} Pa: RMSE {1e3 * y_fit.rmse_length_m:.2f} mm")

    t_end, chains, warmup, samples = (2.0, 2, 100, 100) if args.quick else (10.0, 4, 500, 500)
    pcfg = gj.QuasiStaticConfig(t1=t_end)
    pin = ex.to_inputs(exp, "forward", base, pcfg.t0, pcfg.t1)
    post = gpost.sample(exp.time, exp["robot_length_m"], pin, base, pcfg, chains=chains, warmup=warmup, samples=samples)
    post.idata.to_netcdf(str(out / "posterior.nc"))
    report["posterior"] = post.summary
    for site, prior in zip(("Y", "ext", "n"), gpost.paper_priors()):
        x = np.asarray(post.idata.posterior[site]).ravel()
        report["posterior"]["parameters"][site]["prior_sd"] = (prior.high - prior.low) / np.sqrt(12.0)
        report["posterior"]["parameters"][site]["posterior_over_prior_sd"] = float(x.std() / ((prior.high - prior.low) / np.sqrt(12.0)))
    (out / "report.json").write_text(json.dumps(report, indent=2, default=str) + "\n")
    print(json.dumps(report, indent=2, default=str))


if __name__ == "__main__":
    main()
