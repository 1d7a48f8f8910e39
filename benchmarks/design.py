"""The designed experiment against the published pulse train: the criterion's landscape, and replications that
compare each input's realised precision with the design's prediction.

Run: ``python benchmarks/design.py [--random 1000] [--replications 20] [--workers 16] [--out
benchmarks/results/design.json]``. The design is written to ``--out`` as soon as it is made and each replication to
its partial file as it finishes: ``--design-from OUT --resume`` completes a run that stopped.

What is known: the default fit (``growjax.calibration.fit``, the default likelihood) of the shipped synthetic experiment
(or ``--data``) for ``--for`` (default Y), under ``--growth-law`` (``lockhart``: Lockhart's law for the fit, the
design and the replications' data; with ``--for Y phi_L n_L`` the law's rate and exponent, which the shipped
experiment leaves undetermined, enter with their box's uniform prior). Then:

(a) Landscape: ``growjax.design.design`` with ``--random`` random admissible inputs scored by the criterion; the
    best of them against the optimiser's design (the design must beat it), and the criterion's quantiles over
    the batch.
(b) Replications: ``--replications`` times, a rig drawn from the default tolerance budget and θ at its estimate;
    the design's input and the published pulse train each run by the reference configuration on that rig,
    with fresh white length noise (the fitted noise sd; and 1 kPa pressure noise where ``--sensors`` records it;
    with ``--discrepancy-in-data``, also a fresh draw of the Matérn-3/2 discrepancy the first fit found, the
    residual model the prediction assumes);
    each fitted alone by ``growjax.calibration.fit`` (default likelihood, the rig's errors inferred as parameters of the
    model, as ``growjax fit`` does; ``--no-rig-tangents``: their secants, linearised once at nominal, or with
    ``--relinearise`` taken again where the data put the rig). Reported per input: the
    realised sd of ln θ̂ over the replications against the predicted sd of the experiment alone, the fits'
    mean reported sd and the coverage of their 90 % intervals, and the design's realised sd against the
    published pulse train's. ``--workers`` runs replications in parallel processes (spawned; each compiles).
(c) Safety: the design and the published pulse train run by the reference configuration over ``--safety-draws``
    fresh draws of the rig and θ (:func:`safety`), the runs over the membrane limit and the stroke counted.

With ``--next-drive inverse`` the designed experiment is the stepper's: its step schedule
(``growjax.design.StepperSpace``, what is known carried over from the forward fit), and its baseline in place of
the published pulse train is the stepper driven by the shipped experiment's recorded length (what the shipped
stepper model does); the replications run both on the stepper drive.

With ``--discriminate A B`` (``python benchmarks/design.py --discriminate retraction_folding trapped_air
--duration 3 --knot-spacing 0.1 --random 16 --replications 4``) it checks the design for model discrimination
instead: ``growjax.design.discriminate`` for the pair, then on ``--replications`` seeds data from "base + A" at
its moderate magnitude (in turn "base + B", and the base alone: clean data, where any named effect is a false
alarm), run by ``--maker`` (default the reference configuration) on
the nominal rig with fresh white length noise under the design and under the published pulse train, each given
to ``growjax.discover.discover`` (``--candidates``, default the whole catalogue); reported: how often discovery
names the true effect (for the clean data: "none") under each input, beside each input's predicted min T.
``--with-first`` also reads each seed's designed experiment together with the first experiment made again on the
same robot (the published pulse train over the shipped record, fresh noise): ``growjax.discover.discover`` of the set
over the two, one Y for the robot (``--design-from`` the pair's results file ``--truths retraction_folding
trapped_air none --inputs design --with-first``).

Targets: realised sd within ±25 % of the prediction; coverage 0.80–0.97; the design's realised
interval ≤ 0.5× the published pulse train's; the design beats the best random input; no run of the design crosses
the membrane limit or the stroke on the reference configuration over ``--safety-draws`` (default 100) fresh
draws of the rig and θ.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))


def knowledge_of(args):
    """(Knowledge, experiment, base) from the default fit of ``args.data``."""
    import growjax as gj
    from growjax import calibration as cal
    from growjax import design as gd
    from growjax.cli.loader import recorded_parameters
    from growjax.data import experiment as ex
    from growjax.data import sets as xs

    path = Path(args.data)
    exp = ex.read(path)
    base = gj.replace(gj.reference("forward", growth_law=args.growth_law), **recorded_parameters(path))
    config = gj.Config(t1=float(min(exp.time[-1], 10.0)), adjoint="forward")
    res = cal.fit(xs.ExperimentSet.single(exp, defaults=base), args.design_for, config=config, seed=args.seed)
    return gd.from_fit(res, base), exp, base


def replicate(job: dict) -> dict:
    """One replication: a drawn rig, both inputs run by the reference configuration with fresh noise, each fitted."""
    import jax
    import jax.numpy as jnp

    import growjax as gj
    from growjax import calibration as cal
    from growjax.calibration import discrepancy as dc
    from growjax.data import experiment as ex
    from growjax.data import sets as xs
    from growjax.model.signals import KnotProfile

    clock = time.perf_counter()
    rng = np.random.default_rng([job["seed"], job["index"]])
    drive = job.get("drive", "forward")
    base = gj.replace(gj.reference(drive, growth_law=job.get("growth_law", "reference")), **job["recorded"])
    offsets = {n: float(rng.normal(0.0, u)) if job["rig"] == "drawn" else 0.0 for n, u in job["tolerances"].items()}
    truth = gj.replace(base, **job["estimate"], **{n: gj.get(base, n) * np.exp(b) for n, b in offsets.items()})
    times = np.asarray(job["times"])
    catheter = gj.Sampled(jnp.asarray(job["catheter_t"]), jnp.asarray(job["catheter_m"]))
    if drive == "inverse":
        from growjax.design.space import stepper_inputs

        inputs_of = {label: stepper_inputs(catheter, job["edges"], steps) for label, steps in job["steps"].items()}
    else:
        inputs_of = {
            "design": gj.Inputs(
                catheter_length=catheter,
                pressure_demand=KnotProfile(jnp.asarray(job["knots"]), jnp.asarray(job["demand"])),
            ),
            "published pulse train": gj.Inputs(catheter_length=catheter, pressure_demand=gj.published_pulse()),
        }
    duration = float(job["duration"])
    reference = gj.Config(fidelity=job["maker"], drive=drive, t1=duration)
    config = gj.Config(drive=drive, t1=duration)
    out = {"index": job["index"], "rig_offsets": offsets}
    for label, inputs in inputs_of.items():
        if label not in job["inputs"]:
            continue
        traj = gj.simulate(truth, inputs, reference, ts=np.concatenate([[reference.t0], times]))
        if int(traj.status) != gj.OK:
            out[label] = {"status": gj.status_name(traj.status)}
            continue
        length = np.asarray(traj.length)[1:] + rng.normal(0.0, job["noise_m"], times.size)
        if job.get("discrepancy"):  # δ ~ GP(0, Matérn-3/2), a fresh draw per input
            a, ell = job["discrepancy"]
            key = jax.random.PRNGKey(int(rng.integers(2**31)))
            length = length + np.asarray(dc.draw(key, times, dc.Hyper.of(a, ell, 0.0, 0.0)))
        pressure = None
        if job["pressure"]:
            pressure = np.asarray(traj.pressure)[1:] + rng.normal(0.0, job["pressure_noise"], times.size)
        one = xs.ExperimentSet.single(
            ex.from_arrays(times, length, pressure), drive=drive, defaults=base, inputs=inputs
        )
        res = cal.fit(
            one,
            job["names"],
            likelihood=cal.Likelihood(sigma_pressure=job["pressure_noise"]),
            config=config,
            starts=1,
            scout=16,
            relinearise=job.get("relinearise", False),
            rig_tangents=job.get("rig_tangents", True),
        )
        row = {"status": res.status, "linearisations": res.linearisations}
        for n in job["names"]:
            true = float(job["estimate"][n])
            est, iv = res.estimate[n], res.interval_90[n]
            row[n] = {
                "truth": true,
                "estimate": est,
                "log_error": float(np.log(est / true)),
                "sd_log_reported": None if res.standard_error[n] is None else res.standard_error[n] / est,
                "interval_90": iv,
                "covered": None if iv is None else bool(iv[0] <= true <= iv[1]),
            }
        out[label] = row
    out["wall_s"] = time.perf_counter() - clock
    return out


def summarise(rows: list, names, predicted: dict, baseline: str = "published pulse train") -> dict:
    out = {}
    for label in ("design", baseline):
        good = [r[label] for r in rows if r.get(label, {}).get("status") in ("converged", "max_steps")]
        per = {}
        for n in names:
            err = np.array([g[n]["log_error"] for g in good])
            rep = [g[n]["sd_log_reported"] for g in good if g[n]["sd_log_reported"] is not None]
            cov = [g[n]["covered"] for g in good if g[n]["covered"] is not None]
            realised = float(np.std(err, ddof=1)) if err.size > 1 else None
            pred = predicted[label][n]
            per[n] = {
                "replications": int(err.size),
                "realised_sd_log": realised,
                "rms_log_error": float(np.sqrt(np.mean(err**2))) if err.size else None,
                "mean_log_error": float(np.mean(err)) if err.size else None,
                "predicted_sd_log_alone": pred,
                "realised_over_predicted": None if realised is None else realised / pred,
                "mean_reported_sd_log": float(np.mean(rep)) if rep else None,
                "coverage_90": float(np.mean(cov)) if cov else None,
                # fits that settled far from the truth (a side minimum), against their own reported sd
                "far_off": int(
                    sum(
                        abs(g[n]["log_error"]) > 5.0 * g[n]["sd_log_reported"]
                        for g in good
                        if g[n]["sd_log_reported"] is not None
                    )
                ),
            }
        out[label] = per
    for n in names:
        d, p = out["design"][n]["realised_sd_log"], out[baseline][n]["realised_sd_log"]
        out.setdefault("design_over_published_realised_sd", {})[n] = None if not (d and p) else d / p
    return out


def safety(known, space, designed, n: int, seed: int) -> dict:
    """The designed input ``designed`` and the space's baseline on the reference configuration over ``n`` fresh draws of
    the rig from its budget and θ from its uncertainty (seeded apart from the design's own check): per input, how
    many runs cross the membrane limit, the sensed-pressure ceiling (the limit × the margin), the length ceiling
    and the robot's stroke, and the worst of each."""
    import growjax as gj
    from growjax import design as gd

    clock = time.perf_counter()
    config = gj.Config(fidelity="reference", drive=space.drive, t1=space.duration)
    lim = gj.limits(known.base)
    stroke = float(known.base.robot.stroke)
    drawn = gd.draws(known, n, seed=seed + 1000)
    out = {"draws": n, "configuration": "reference", "limits": lim.summary(), "stroke_m": stroke}
    for label, inputs in (("design", designed), (space.baseline_label, space.baseline_inputs())):
        res = gd.check(
            gd.stack([inputs]), known, config, space.times, gj.input_breaks(inputs, config), lim, drawn, keep_runs=True
        )
        pressure, length = np.max(res.pressure[0], axis=-1), np.max(res.length[0], axis=-1)
        out[label] = {
            "runs_completed": int(np.sum(np.all(np.isfinite(res.length[0]), axis=-1))),
            "over_membrane_limit": int(np.sum(pressure > lim.membrane_limit)),
            "over_pressure_ceiling": int(np.sum(pressure > lim.pressure_ceiling)),
            "over_length_ceiling": int(np.sum(length > lim.length_ceiling)),
            "over_stroke": int(np.sum(length > stroke)),
            "peak_pressure_Pa": float(np.max(pressure)),
            "peak_length_m": float(np.max(length)),
        }
    out["wall_s"] = time.perf_counter() - clock
    return out


def landscape_of(summary: dict, sensors, wall_s, baseline: str = "published pulse train") -> dict:
    """The landscape's record of a design's summary: the random batch against the design and the baseline."""
    crit = {r["input"]: r["criterion"] for r in summary["table"] if tuple(r["sensors"]) == sensors}
    return {
        "random_admissible": summary["random"]["admissible"],
        "random_drawn": summary["random"]["drawn"],
        "random_best_criterion": summary["random"]["criterion_best"],
        "random_quantiles": summary["random"]["criterion_quantiles"],
        "design_criterion": crit["design"],
        "published_criterion": crit[baseline],
        "design_beats_best_random": bool(crit["design"] < summary["random"]["criterion_best"]),
        "design_wall_s": wall_s,
    }


def first_run(params, exp, base, maker, rng, noise: float):
    """The first experiment again, on the robot with the hidden effect: the shipped experiment's inputs (the
    published pulse train, its catheter) over its record."""
    from growjax.data import experiment as ex

    t = np.asarray(exp.time, float)
    return _measured_run(
        "first", ex.Experiment(t, {"catheter_length_m": exp["catheter_length_m"]}), params, base, maker, rng, noise
    )


def designed_run(params, space, x, exp, base, maker, rng, noise: float):
    """The designed experiment as a run of the set: its demand, then at rest (0 Pa) to the first experiment's end
    (the set's runs share one simulated span); scored over the design's duration only (its window)."""
    from growjax.data import experiment as ex

    t_end = float(exp.time[-1])
    t = np.round(space.sample_interval * np.arange(1, int(round(t_end / space.sample_interval)) + 1), 12)
    demand = np.where(t <= space.duration + 1e-9, np.interp(t, space.knots, np.asarray(space.demand(x))), 0.0)
    catheter = np.interp(t, np.asarray(exp.time), np.asarray(exp["catheter_length_m"]))
    record = ex.Experiment(t, {"pressure_demand_Pa": demand, "catheter_length_m": catheter})
    return _measured_run("designed", record, params, base, maker, rng, noise, window=(0.0, space.duration))


def _measured_run(name, record, params, base, maker, rng, noise: float, window=None):
    """A run of the set named ``name``: the inputs of ``record`` (its columns, as a lab's CSV gives them) run on
    ``params`` by ``maker``'s configuration over the record, its length with fresh white noise of sd ``noise`` (m)."""
    import growjax as gj
    from growjax.data import experiment as ex
    from growjax.data.sets import Run

    t = np.asarray(record.time, float)
    inputs = ex.to_inputs(record, "forward", base, 0.0, float(t[-1]))
    config = gj.Config(fidelity=maker.fidelity, t1=float(t[-1]))
    length = np.asarray(gj.simulate(params, inputs, config, ts=np.concatenate([[config.t0], t])).length)[1:]
    series = {**record.series, "robot_length_m": length + rng.normal(0.0, noise, t.size)}
    return Run(name, ex.Experiment(t, series), window=window)


def discriminate(args, known, exp, base) -> dict:
    """The model-discrimination check of ``--discriminate A B`` (see the module docstring)."""
    import growjax as gj
    from growjax import design as gd
    from growjax.data import experiment as ex
    from growjax.data import synthetic as syn
    from growjax.data.sets import ExperimentSet
    from growjax.discover import discover

    a, b = args.discriminate
    space = gd.DesignSpace(
        args.duration,
        gj.limits(base).pressure_ceiling,
        gd.catheter_of(exp, args.duration),
        knot_spacing=args.knot_spacing,
    )
    if args.design_from:  # an earlier run's design
        summary = json.loads(Path(args.design_from).read_text())["design"]
        x = space.unconstrained(np.asarray(summary["design"]["demand_Pa"]))
    else:
        result = gd.discriminate(
            known,
            space,
            (a, b),
            random=args.random,
            starts=args.starts,
            iterations=args.iterations,
            seed=args.seed,
            progress=True,
        )
        summary, x = result.summary(), result.x
    print(json.dumps({r["input"]: r["T"] for r in summary["table"]}, indent=1), flush=True)
    inputs = {"design": space.inputs(x), "published pulse train": gd.published_inputs(space)}
    inputs = {label: inp for label, inp in inputs.items() if label in args.inputs}
    maker = gj.Config(fidelity=args.maker, t1=args.duration)
    times = np.asarray(space.times)
    base_names = [] if args.hold_base else list(known.names)  # held: at the first experiment's estimate
    truths = args.truths or (a, b, "none")  # "none": clean data, where naming any effect is a false alarm
    rows = []
    for truth in truths:
        params = known.base if truth == "none" else gj.with_effects(known.base, syn.make_effect(truth))
        for index in range(args.replications):
            rng = np.random.default_rng([args.seed, index, 11 if truth != "none" else 13])
            row = {"truth": truth, "index": index}
            for label, inp in inputs.items():
                traj = gj.simulate(params, inp, maker, ts=np.concatenate([[maker.t0], times]))
                length = np.asarray(traj.length)[1:] + rng.normal(0.0, float(known.hyper.noise), times.size)
                found = discover(
                    ExperimentSet.single(ex.from_arrays(times, length), defaults=known.base, inputs=inp),
                    config=gj.Config(t1=args.duration),
                    base_free=base_names,
                    candidates=args.candidates,
                )
                row[label] = {
                    "effect": found.effect,
                    "named": found.effect == truth,
                    "confounded_with": list(found.confounded_with or []),
                }
                if args.with_first and label == "design":
                    runs = (
                        first_run(params, exp, base, maker, rng, float(known.hyper.noise)),
                        designed_run(params, space, x, exp, base, maker, rng, float(known.hyper.noise)),
                    )
                    both = discover(
                        ExperimentSet(runs), config=gj.Config(t1=float(exp.time[-1])), candidates=args.candidates
                    )
                    row["design with the first"] = {
                        "effect": both.effect,
                        "named": both.effect == truth,
                        "confounded_with": list(both.confounded_with or []),
                    }
            rows.append(row)
            print(json.dumps(row), flush=True)
    labels = list(inputs) + (["design with the first"] if args.with_first and "design" in inputs else [])
    rate = {
        label: {t: float(np.mean([r[label]["named"] for r in rows if r["truth"] == t])) for t in truths}
        for label in labels
    }
    return {"design": summary, "replications": rows, "named_rate": rate}


def main():
    from growjax.data.experiment import shared_experiment_dir  # noqa: F401 (import check before the long run)

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv"))
    ap.add_argument("--for", dest="design_for", nargs="+", default=["Y"])
    ap.add_argument("--sensors", default="length", choices=["length", "length,pressure"])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--random", type=int, default=1000, help="random admissible inputs of the landscape")
    ap.add_argument("--starts", type=int, default=3)
    ap.add_argument("--iterations", type=int, default=30)
    ap.add_argument("--replications", type=int, default=20)
    ap.add_argument("--workers", type=int, default=1, help="replications run at a time (spawned processes)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--maker",
        choices=["reference", "fast"],
        default="reference",
        help="the configuration that makes the replications' data (fast: no model error, a diagnostic)",
    )
    ap.add_argument(
        "--rig",
        choices=["drawn", "nominal"],
        default="drawn",
        help="the replications' rig: drawn from the tolerance budget, or nominal (a diagnostic)",
    )
    ap.add_argument(
        "--next-drive",
        choices=["forward", "inverse"],
        default="forward",
        help="the designed experiment's drive (inverse: the stepper's schedule; see the docstring)",
    )
    ap.add_argument(
        "--inputs",
        nargs="+",
        default=["design", "published pulse train"],
        choices=["design", "published pulse train", "recorded length as demand"],
        help="the inputs replicated (with --discriminate: whose data discovery reads)",
    )
    ap.add_argument(
        "--rig-tangents",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the replications' fits make the rig's errors parameters of the model (exact tangents, "
        "as growjax fit; default); --no-rig-tangents: secants, linearised once at nominal",
    )
    ap.add_argument(
        "--relinearise",
        action="store_true",
        help="with --no-rig-tangents: the secants taken again where the data put the rig",
    )
    ap.add_argument(
        "--discrepancy-in-data",
        action="store_true",
        help="the replications' data also carry a fresh draw of the discrepancy the first fit found",
    )
    ap.add_argument(
        "--safety-draws",
        type=int,
        default=100,
        help="fresh draws of the rig and θ the design is run on by the reference configuration (0: none)",
    )
    ap.add_argument(
        "--resume",
        action="store_true",
        help="with --design-from: keep the replications in --out's partial file; run the rest",
    )
    ap.add_argument(
        "--design-from",
        default=None,
        metavar="DESIGN.json",
        help="take the design (and its prediction) from this benchmark's earlier results file",
    )
    ap.add_argument(
        "--discriminate",
        nargs=2,
        default=None,
        metavar="EFFECT",
        help="check the design for telling two catalogue effects apart instead (see the docstring)",
    )
    ap.add_argument("--knot-spacing", type=float, default=0.5, help="s between the demand's knots")
    ap.add_argument(
        "--growth-law",
        choices=["reference", "lockhart"],
        default="reference",
        help="the growth law of the fit, the design and the replications' data (lockhart: with --for Y "
        "phi_L n_L, a design for the law's rate and exponent)",
    )
    ap.add_argument("--candidates", nargs="+", default=None, help="with --discriminate: discovery's candidates")
    ap.add_argument(
        "--truths",
        nargs="+",
        default=None,
        metavar="EFFECT",
        help="with --discriminate: the hidden effects replicated ('none': clean data; default A B none)",
    )
    ap.add_argument(
        "--hold-base",
        action="store_true",
        help="with --discriminate: discovery holds the base parameters at the first experiment's "
        "estimate (the designed experiment read with what is known) instead of refitting them",
    )
    ap.add_argument(
        "--with-first",
        action="store_true",
        help="with --discriminate: also read each designed experiment together with the first one made "
        "again on the same robot (the published pulse train, fresh noise): discovery over the set "
        "of the two (growjax.discover.discover of the set, one Y for the robot)",
    )
    ap.add_argument(
        "--out",
        default=None,
        help="results file (default benchmarks/results/design.json, design_discrimination.json with --discriminate)",
    )
    args = ap.parse_args()
    if args.resume and not args.design_from:
        ap.error("--resume takes up the replications of a design: give it --design-from (the run's --out)")
    args.out = args.out or str(
        REPO / "benchmarks" / "results" / ("design_discrimination.json" if args.discriminate else "design.json")
    )
    from _environment import environment

    import growjax as gj
    from growjax import design as gd
    from growjax.cli.loader import recorded_parameters

    clock = time.perf_counter()
    known, exp, base = knowledge_of(args)
    if args.discriminate:
        record = {
            "environment": environment(),
            "arguments": vars(args),
            "knowledge": known.summary(),
            **discriminate(args, known, exp, base),
            "growjax": gj.__version__,
        }
        record["wall_s"] = time.perf_counter() - clock
        print(json.dumps(record["named_rate"], indent=1))
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(record, indent=1, default=str) + "\n")
        print(f"wrote {args.out}")
        return
    if args.next_drive == "inverse":
        base = gj.replace(gj.reference("inverse", growth_law=args.growth_law), **recorded_parameters(Path(args.data)))
        known = known.on(base)
        space = gd.stepper_space(base, args.duration, exp)
        args.inputs = [space.baseline_label if i == "published pulse train" else i for i in args.inputs]
    else:
        space = gd.DesignSpace(
            args.duration,
            gj.limits(base).pressure_ceiling,
            gd.catheter_of(exp, args.duration),
            knot_spacing=args.knot_spacing,
        )
    baseline = space.baseline_label
    sensors = tuple(args.sensors.split(","))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.design_from:  # an earlier run's design and landscape (or a `growjax design` summary.json)
        earlier = json.loads(Path(args.design_from).read_text())
        if "landscape" not in earlier:
            earlier = {"design": earlier, "landscape": landscape_of(earlier, sensors, None, baseline)}
        summary, landscape = earlier["design"], earlier["landscape"]
        if args.next_drive == "inverse":
            x = np.asarray(summary["design"]["steps"], float)
        else:
            x = space.unconstrained(np.asarray(summary["design"]["demand_Pa"]))
    else:
        t = time.perf_counter()
        result = gd.design(
            known,
            space,
            sensors=sensors,
            random=args.random,
            starts=args.starts,
            iterations=args.iterations,
            seed=args.seed,
            progress=True,
        )
        design_wall = time.perf_counter() - t
        space.write_csv(out.with_suffix(".csv"), result.x)
        gd.design_figure(result, out.with_suffix(".png"))
        summary = result.summary()
        x = result.x
        landscape = {
            **landscape_of(summary, sensors, design_wall, baseline),
            "random_criterion": result.random.criterion.tolist(),
        }
    if not args.design_from:  # the design alone, so that ``--design-from`` can take it up if the replications stop
        out.write_text(
            json.dumps(
                {
                    "environment": environment(),
                    "arguments": vars(args),
                    "knowledge": known.summary(),
                    "design": summary,
                    "landscape": landscape,
                    "growjax": gj.__version__,
                },
                indent=1,
                default=str,
            )
            + "\n"
        )
    table = {r["input"]: r["parameters"] for r in summary["table"] if tuple(r["sensors"]) == sensors}
    print(json.dumps({k: v for k, v in landscape.items() if k != "random_criterion"}, indent=1), flush=True)
    safe = safety(known, space, space.inputs(x), args.safety_draws, args.seed) if args.safety_draws else None
    print(json.dumps(safe, indent=1), flush=True)
    names = list(known.names)
    predicted = {label: {n: table[label][n]["sd_log_alone"] for n in names} for label in ("design", baseline)}
    t_cath = np.asarray(space.catheter.times) if hasattr(space.catheter, "times") else np.array([0.0, 1.0])
    c_cath = np.asarray(space.catheter.values) if hasattr(space.catheter, "values") else np.zeros(2)
    job = {
        "seed": args.seed,
        "recorded": recorded_parameters(Path(args.data)),
        "tolerances": dict(known.tolerances),
        "estimate": dict(zip(names, map(float, known.estimate))),
        "names": names,
        "times": np.asarray(space.times).tolist(),
        "catheter_t": t_cath.tolist(),
        "catheter_m": c_cath.tolist(),
        "drive": space.drive,
        "duration": args.duration,
        "noise_m": float(known.hyper.noise),
        "pressure": "pressure" in sensors,
        "pressure_noise": 1e3,
        "maker": args.maker,
        "rig": args.rig,
        "inputs": args.inputs,
        "relinearise": args.relinearise,
        "rig_tangents": args.rig_tangents,
        "growth_law": args.growth_law,
        "discrepancy": [float(known.hyper.amplitude), float(known.hyper.time_scale)]
        if args.discrepancy_in_data
        else None,
    }
    if space.drive == "inverse":
        job.update(
            edges=space.edges.tolist(), steps={"design": np.asarray(x).tolist(), baseline: space.baseline().tolist()}
        )
    else:
        job.update(knots=space.knots.tolist(), demand=np.asarray(space.demand(x)).tolist())
    partial = out.with_suffix(".partial.jsonl")  # replications as they finish
    rows = []
    if args.resume and partial.exists():
        rows = [json.loads(line) for line in partial.read_text().splitlines() if line.strip()]
    else:
        partial.write_text("")
    done = {r["index"] for r in rows}
    jobs = [{**job, "index": i} for i in range(args.replications) if i not in done]

    def keep(row):
        rows.append(row)
        with partial.open("a") as fh:
            fh.write(json.dumps(row, default=str) + "\n")
        print(json.dumps({k: v for k, v in row.items() if k != "rig_offsets"}), flush=True)

    if args.workers > 1:
        import multiprocessing as mp

        with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as pool:
            for row in pool.map(replicate, jobs):
                keep(row)
    else:
        for j in jobs:
            keep(replicate(j))
    rows.sort(key=lambda r: r["index"])
    replications = summarise(rows, names, predicted, baseline)
    print(json.dumps(replications, indent=1), flush=True)
    record = {
        "environment": environment(),
        "arguments": vars(args),
        "knowledge": known.summary(),
        "design": summary,
        "landscape": landscape,
        "safety": safe,
        "replications": replications,
        "rows": rows,
        "wall_s": time.perf_counter() - clock,
        "growjax": gj.__version__,
    }
    out.write_text(json.dumps(record, indent=1, default=str) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
