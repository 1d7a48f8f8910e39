"""``growjax posterior [DATA]``: the NUTS posterior of the growth law's parameters and the noise (writes
posterior.nc); with ``--hierarchical NAME`` over a set of robots, the population of their NAME and the predictive
for a new robot of the same build (writes population.nc and population.png)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from growjax.cli import loader, options
from growjax.cli._summary import data_name, mm, origin_lines, value
from growjax.cli.command import Process, RunFailed, note, out_dir
from growjax.cli.options import count, option


def _whole_loop(args) -> bool:
    """Thousands of gradients through the solver: its loop compiled whole (not for the emulator or a population)."""
    return not args.emulate and args.hierarchical is None


NAME = "posterior"
HELP = "NUTS posterior of Y, ext, n (or Y, phi_L, n_L) and the noise; of a population of robots with --hierarchical"
PROCESS = Process(cpu_devices=True, devices_at_least="chains", whole_loop=_whole_loop)  # chains one per device
OPTIONS = (
    option(
        "--hierarchical",
        default=None,
        metavar="NAME",
        help="a TOML manifest of several robots (or several files): each robot's NAME drawn from a "
        "log-normal population whose median and spread are sampled, the data entering through "
        "the set's joint fit; with the predictive for a new robot (default: off)",
    ),
    option(
        "--predict",
        default=None,
        metavar="CSV",
        help="with --hierarchical: the input (demand, catheter) of the new robot's experiment "
        "(default: the set's first experiment's)",
    ),
    option(
        "--law",
        choices=["reference", "lockhart"],
        default="reference",
        help="growth law: the published velocity term, or Lockhart's",
    ),
    option(
        "--emulate",
        action="store_true",
        help="sample through a validated emulator of the model (fast; worth it where the data leave "
        "directions flat, as ext and n of the published law)",
    ),
    option("--chains", type=count(), default=4, help="NUTS chains"),
    option("--warmup", type=count(0), default=500, help="warm-up draws per chain"),
    option("--samples", type=count(), default=500, help="kept draws per chain"),
)


def add_arguments(parser) -> None:
    """The shared options (several DATA), the sampler's, ``--quiet``, the likelihood's."""
    options.shared(parser, NAME, many=True)
    options.add(parser, OPTIONS)
    options.quiet(parser)
    options.likelihood(parser)


def run(args) -> dict:
    """The posterior of one experiment, or the population of a set's robots (``--hierarchical``); the summary,
    RunFailed where the chains did not mix."""
    if args.hierarchical is not None:
        return _population(args, loader.load(args, as_set=True))
    if loader.is_set(args.data or []):
        raise ValueError(
            "a posterior over several experiments is the population's: give --hierarchical NAME "
            "(for one robot's experiments, `growjax fit` gives their joint intervals)"
        )
    data = loader.load(args, growth_law=args.law)
    if "robot_length_m" not in data.experiment:
        raise ValueError(f"{data.path} has no robot_length_m column to calibrate against")
    config = options.make_config(args, args.drive, adjoint="forward")
    res = _sample(args, data, config)
    out = out_dir(args)
    res.idata.to_netcdf(str(out / "posterior.nc"))
    summary = {
        "command": NAME,
        "data": str(data.path),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fidelity": config.fidelity,
        "growth_law": args.law,
        "fixed_parameters": data.origin,
        **res.summary,
        "inference_data": str(out / "posterior.nc"),
    }
    rhat = summary.get("rhat_max")
    if args.chains > 1 and (rhat is None or not math.isfinite(rhat) or rhat > 1.1):
        raise RunFailed(f"the chains did not mix (R-hat max {rhat}); run more --warmup and --samples", summary)
    return summary


def _population(args, data) -> dict:
    """``growjax posterior SET.toml --hierarchical NAME``: the joint fit of the set, then the population of its
    robots' NAME, and the predictive for a new robot of the same build."""
    from growjax.model.params import resolve_name
    from growjax.plotting import population_figure
    from growjax.posterior import population as pop

    config = options.make_config(args, args.drive, adjoint="forward")
    exps = data.experiments
    name = resolve_name(exps.runs[0].base(), args.hierarchical)
    if len(exps.robots) < 2:
        raise ValueError(
            f"--hierarchical needs experiments of two or more robots, got robot {exps.robots[0]!r}: "
            "name each experiment's robot in a manifest"
        )
    started = note(args, f"posterior: joint fit of {name}@robot over {len(exps)} experiments")
    fit = _joint_fit(args, exps, name, config)
    if fit.status != "converged":
        raise RunFailed(f"the joint fit did not converge ({fit.status})", {"command": NAME, **fit.summary()})
    note(args, f"posterior: joint fit done in {time.perf_counter() - started:.1f} s; NUTS on the population")
    post = _population_sample(args, fit, name)
    run = _new_robot(args, exps)
    band = _predict(args, post, run, config)
    out = out_dir(args)
    nc = pop.save(post, out / "population.nc")
    measured = (run.times, run.length) if "robot_length_m" in run.experiment else None
    fig = population_figure(post, band, out / "population.png", measured=measured)
    summary = {
        "command": NAME,
        "hierarchical": name,
        "data": list(data.sources),
        "drive": args.drive,
        "t_end_s": args.t_end,
        "fidelity": config.fidelity,
        "chains": args.chains,
        "warmup": args.warmup,
        "samples": args.samples,
        **post.summary(),
        "joint_fit": fit.summary(),
        "new_robot": {
            "input": args.predict or run.name,
            "median_final_length_m": float(band["median"][-1]),
            "band_90_final_length_m": [float(band["lower"][-1]), float(band["upper"][-1])],
            "median_band_width_m": float(np.median(band["upper"] - band["lower"])),
            "failed_draws": band["failed"],
        },
        "wall_s": time.perf_counter() - started,
        "posterior_file": str(nc),
        "figure": str(fig),
    }
    rhat = post.diagnostics["mu"]["r_hat"]
    if args.chains > 1 and (rhat is None or not math.isfinite(rhat) or rhat > 1.1):
        raise RunFailed(f"the chains did not mix (R-hat of mu {rhat}); run more --warmup and --samples", summary)
    return summary


def _new_robot(args, exps):
    """The run a new robot is predicted on: ``--predict``'s input on the set's first rig, or the first run."""
    from growjax.data import experiment as ex
    from growjax.data import sets as xs

    if not args.predict:
        return exps.runs[0]
    first = exps.runs[0]
    new = ex.read(Path(args.predict), catheter=args.catheter)
    return xs.Run("new robot", new, drive=first.drive, robot="new robot", rig=first.rig, parameters=first.parameters)


# -- the workflow's calls ---------------------------------------------------------------------------------------


def _sample(args, data, config):
    """The posterior of one experiment (`growjax.posterior.sample`) under the flags' likelihood."""
    from growjax import posterior as gpost
    from growjax.data import sets as xs

    exps = xs.ExperimentSet.single(
        data.experiment,
        name=data.path.stem or "experiment",
        drive=args.drive,
        defaults=data.base(),
        window=options.scored_window(args, config),
    )
    return gpost.sample(
        exps,
        config=config,
        priors=gpost.paper_priors() if args.law == "reference" else gpost.lockhart_priors(),
        likelihood=options.likelihood_of(args),
        chains=args.chains,
        warmup=args.warmup,
        samples=args.samples,
        seed=args.seed,
        progress=not args.quiet,
        emulate=args.emulate,
    )


def _joint_fit(args, exps, name: str, config):
    """The set's joint fit of ``name`` per robot (`growjax.calibration.fit`)."""
    from growjax import calibration

    return calibration.fit(
        exps,
        [f"{name}@robot"],
        likelihood=options.likelihood_of(args),
        config=config,
        starts=1,
        scout=16,
        seed=args.seed,
    )


def _population_sample(args, fit, name: str):
    """The population of the robots' ``name`` from the joint fit (`growjax.posterior.population.sample`)."""
    from growjax.posterior import population as pop

    return pop.sample_population(
        fit, name, chains=args.chains, warmup=args.warmup, samples=args.samples, seed=args.seed
    )


def _predict(args, post, run, config) -> dict:
    """The predictive band of a new robot on ``run`` (`growjax.posterior.population.predict_new_robot`)."""
    from growjax.posterior import population as pop

    return pop.predict_new_robot(post, run, config, draws=400, seed=args.seed)


# -- the summary for people -------------------------------------------------------------------------------------


def summary_lines(s: dict) -> list[str]:
    """The parameters' means and 90 % intervals, the chains' diagnostics, the file (a population's: its median,
    spread, robots and the new robot's prediction)."""
    if s.get("hierarchical"):
        return _population_lines(s)
    lines = [
        f"posterior: {data_name(s)}, {s['growth_law']} growth law, {s['chains']} chains × "
        f"({s['warmup']} + {s['samples']})",
        *origin_lines(s["fixed_parameters"]),
    ]
    for p, v in s["parameters"].items():
        lo, hi = v["interval_90"]
        if p in ("sigma", "delta_amplitude"):
            label = "σ" if p == "sigma" else "discrepancy amplitude"
            lines.append(f"  {label} = {mm(v['mean'])} (90 % {mm(lo)} – {mm(hi)})")
        elif p == "delta_time_scale":
            lines.append(f"  discrepancy time scale = {v['mean']:.2g} s (90 % {lo:.2g} – {hi:.2g} s)")
        elif p == "noise_time":
            lines.append(
                f"  noise correlation time = {1e3 * v['mean']:.2g} ms (90 % {1e3 * lo:.2g} – {1e3 * hi:.2g} ms)"
            )
        else:
            lines.append(f"  {p} = {value(p, v['mean'])} (90 % {value(p, lo)} – {value(p, hi)})")
    lines.append(
        f"  R-hat max {s['rhat_max']:.3f}, bulk ESS min {s['ess_bulk_min']:.0f}, divergences "
        f"{s['divergences']}, measured points in the 90 % band {s['coverage_90']:.2f}; {s['wall_s']:.0f} s"
    )
    lines.append(f"  wrote {s['inference_data']}")
    return lines


def _population_lines(s: dict) -> list[str]:
    p = s["parameter"]
    med, sd = s["population_median"], s["population_sd_log"]
    fit = s["joint_fit"]
    lines = [
        f"posterior: {data_name(s)}, population of {len(s['robots'])} robots' {p}, {s['chains']} chains × "
        f"({s['warmup']} + {s['samples']}); the data through the joint fit ({fit['status']}, rig {fit['rig']})",
        f"  population median = {value(p, med['median'])} (90 % {value(p, med['interval_90'][0])} – "
        f"{value(p, med['interval_90'][1])}); spread (sd of ln) = {sd['median']:.3f} "
        f"(90 % {sd['interval_90'][0]:.3f} – {sd['interval_90'][1]:.3f})",
    ]
    for robot, v in s["robot_posterior"].items():
        lines.append(f"  {robot}: {value(p, v['median'])} (90 % {value(p, v['lower_90'])} – {value(p, v['upper_90'])})")
    new = s["new_robot"]
    lo, hi = new["band_90_final_length_m"]
    lines.append(
        f"  a new robot under {new['input']}: final length {mm(new['median_final_length_m'])} "
        f"(90 % {mm(lo)} – {mm(hi)}); median band width {mm(new['median_band_width_m'])}"
    )
    d = s["diagnostics"]
    lines.append(
        f"  R-hat of mu {d['mu']['r_hat'] or float('nan'):.3f}, of s {d['s']['r_hat'] or float('nan'):.3f}; "
        f"ESS min {min(d[k]['ess'] for k in ('mu', 's', 'ln_theta')):.0f}; divergences {d['divergences']}; "
        f"{s['wall_s']:.0f} s"
    )
    lines.append(f"  wrote {s['posterior_file']}, {s['figure']}")
    return lines


__all__ = ["HELP", "NAME", "OPTIONS", "PROCESS", "add_arguments", "run", "summary_lines"]
