"""Write docs/results.md, the public MAMMOBOT experiment's results, from the results files in calibration/results/.

Run from the repository root::

    python calibration/results_page.py [--results calibration/results] [--out docs/results.md]

The files, each written by the script named in it (with the machine and versions it ran on):

- ``paper.json``: ``python calibration/paper_public.py`` (simulations, the 500-set sweep, Sobol indices, discovery);
- ``calibration.json``: ``python calibration/calibrate_public.py`` (fits and posteriors under the default
  likelihood, LOO, the independent-noise contrast).

The page is regenerated from the files alone: rerun the scripts, then this one, never edit the page. Both files
must come from one version of growjax.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "calibration" / "results"
Y = "robot.yield_pressure"
SYMBOLS = {Y: "Y", "robot.growth_exponent": "n", "robot.extensibility": "ext"}
SITES = {
    "Y": ("Y", 1.0, "Pa"),
    "phi_L": ("φ_L", 1e3, "mm/s"),
    "n_L": ("n_L", 1.0, ""),
    "ext": ("ext", 1.0, ""),
    "n": ("n", 1.0, ""),
}  # site: (symbol, factor from SI, unit shown)
BUDGET_NAMES = {
    "noise": "sensor noise",
    "discrepancy": "discrepancy",
    "hyperparameters": "the hyperparameters' spread",
    "fast_model_error": "fast configuration's allowance",
}
# The paper's headline figures (forward model; actuation and hydraulic model, the stepper).
PAPER = {"forward": (1.7e-3, 3.5), "stepper": (2.5e-3, 5.0)}  # RMSE m, % of the final length

HEADER = """# Results on the public experiment

growjax on the experiment the paper validates against: 10 s of the robot's length and the catheter's, forward
drive, read as `mammobot` ([Data formats](data.md#the-public-mammobot-experiment)). Every figure comes from a
script in `calibration/` whose results are committed in `calibration/results/`; the command is beside each.
{environment}
"""

STEPPER = """
The stepper model cannot follow the length more closely than its step grid: one full motor step is 3.1 mm of
robot length, and the shipped step controller issues a step only when the demand is half a step away. Length
control closes that gap: see `python benchmarks/control.py` on the [Benchmarks](benchmarks.md) page.
"""

# -- formatting ------------------------------------------------------------------------------------------------


def mm(x) -> str:
    return f"{1e3 * float(x):.2f} mm"


def pa(x) -> str:
    return f"{float(x):.0f} Pa"


def pa_interval(lo, hi) -> str:
    return f"{float(lo):.0f}–{float(hi):.0f} Pa"


def environment(*records: dict) -> str:
    """One line naming the version, Python, jax and machine(s) the results files were made with; SystemExit where
    they come from different versions of growjax (rerun the older script)."""
    envs = [r["environment"] for r in records]
    versions = {e["growjax"] for e in envs}
    if len(versions) > 1:
        raise SystemExit(f"the results files come from growjax {sorted(versions)}: rerun the older script")
    machines = ", ".join(dict.fromkeys(f"{e['machine']} ({e['device']})" for e in envs))
    e = envs[0]
    return f"All figures: growjax {e['growjax']}, Python {e['python']}, jax {e['jax']}, on {machines}."


def table(head: tuple, rows: list) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


# -- sections --------------------------------------------------------------------------------------------------


def _rmse(rmse_m: float, final_m: float) -> str:
    return f"{mm(rmse_m)} ({100 * rmse_m / final_m:.1f} %)"


def paper_section(p: dict) -> str:
    best, final = p["sweep_best"], p["measured_final_length_m"]
    paper = {k: f"{1e3 * r:.1f} mm ({pct:g} %)" for k, (r, pct) in PAPER.items()}
    rows = [
        (
            "length RMSE, forward model (PID, ideal torque sources), published parameters",
            _rmse(p["forward_rmse_m"], final),
            paper["forward"],
            f"`{p['commands']['forward']['command']}`",
        ),
        (
            "length RMSE, stepper model with the shipped step controller at 3 Hz",
            _rmse(p["stepper_rmse_m"], final),
            paper["stepper"],
            f"`{p['commands']['stepper']['command']}`",
        ),
        (
            f"best of the {p['sweep_n']}-set Latin hypercube",
            f"Y = {best['parameters'][Y] / 1e3:.2f} kPa, {mm(best['rmse_length_m'])}",
            "Y near 8 kPa, 1.7 mm",
            "`growjax sweep mammobot`",
        ),
        (
            "safe pressure of the membrane, 2 t_m σ_y / (r_o · SF)",
            f"{p['pressure_limit_Pa'] / 1e3:.1f} kPa",
            "373.3 kPa",
            "`growjax params`",
        ),
    ]
    return (
        "\n## Against the paper\n\n`python calibration/paper_public.py` runs the commands of this section. "
        f"Percentages are of the measured final length, {mm(final)}.\n\n"
        + table(("quantity", "growjax", "paper", "command"), rows)
        + STEPPER
    )


def _range(r: dict) -> str:
    """A swept range as the page writes it (Y in kPa)."""
    scale, unit = (1e3, " kPa") if r["name"] == Y else (1.0, "")
    return f"{SYMBOLS.get(r['name'], r['name'])} {r['low'] / scale:g}–{r['high'] / scale:g}{unit}"


def sensitivity_section(p: dict) -> str:
    sob = p["sobol"]
    names = [SYMBOLS.get(n, n) for n in sob["names"]]
    box = ", ".join(_range(r) for r in p["sweep_ranges"])
    outputs = {"rmse_length_m": "the RMSE", "final_length_m": "the final length"}
    parts = []
    for key, label in outputs.items():
        s = sob["indices"].get(key)
        if not s or "error" in s:
            parts.append(f"the indices of {label} are not defined ({(s or {}).get('error', 'not computed')})")
            continue
        i = names.index("Y")
        parts.append(f"for {label} Y's first-order index is {s['S1'][i]:.2f} and its total index {s['ST'][i]:.2f}")
    others = [k for k, n in enumerate(names) if n != "Y"]
    largest = max(
        (abs(s[q][k]) for s in sob["indices"].values() if "error" not in s for q in ("S1", "ST") for k in others),
        default=math.nan,
    )
    tail = (
        f"{' and '.join(names[k] for k in others)} are indistinguishable from zero (no index above "
        f"{largest:.2g} in magnitude)"
        if largest < 0.01
        else f"the largest index of {' or '.join(names[k] for k in others)} is {largest:.2f}"
    )
    return (
        f"\n**Sensitivity.** Sobol indices over the paper's box ({box}; {sob['n_runs']} runs, "
        f"`growjax sweep mammobot --sobol`): {'; '.join(parts)}; {tail}. Under the published growth law the "
        "velocity term is about 1e-10 of the other forces on the rod, so the length does not depend on n and ext.\n"
    )


def _bound(site: str, value: float) -> str:
    symbol, factor, unit = SITES.get(site, (site, 1.0, ""))
    return f"{symbol} at {factor * value:g}{' ' + unit if unit else ''}"


DETERMINED = 0.5  # posterior sd ÷ prior sd below which the data determine a parameter


def _at_edge(post: dict) -> list[str]:
    """Determined sites whose 90 % interval reaches within 5 % (of the box, in ln θ where log) of a prior bound."""
    out = []
    for site, prior in post["priors"].items():
        if post["posterior_sd_over_prior_sd"][site] >= DETERMINED:
            continue
        lo, hi = post["parameters"][site]["interval_90"]
        f = (lambda x: math.log(x)) if prior["log"] else (lambda x: x)
        span = f(prior["high"]) - f(prior["low"])
        if f(lo) - f(prior["low"]) < 0.05 * span:
            out.append(_bound(site, prior["low"]))
        elif f(prior["high"]) - f(hi) < 0.05 * span:
            out.append(_bound(site, prior["high"]))
    return out


def _lockhart_note(lock: dict, scored: int) -> str:
    ratio = lock["posterior_sd_over_prior_sd"]
    symbol = lambda site: SITES.get(site, (site,))[0]  # noqa: E731
    edges = _at_edge(lock)
    loose = [s for s, r in ratio.items() if r >= DETERMINED]
    shown = ", ".join(f"{symbol(s)} {r:.2f}" for s, r in ratio.items())
    if loose:
        text = (
            f"Under this likelihood the {scored} scored samples leave the Lockhart law's "
            f"{' and '.join(symbol(s) for s in loose)} close to their priors (posterior sd ÷ prior sd {shown}): "
            "with the residuals' correlation and the rig's tolerances accounted for, the length does not single "
            "out the growth law's form."
        )
    else:
        text = f"The Lockhart posterior determines its parameters (posterior sd ÷ prior sd {shown})."
    if edges:
        text += f" Its 90 % interval reaches the edge of the prior box for {'; '.join(edges)}."
    if any(e.startswith("n_L at") for e in edges) and lock["parameters"]["n_L"]["mean"] < 0.5:
        text += (
            " The data ask for a growth speed that hardly depends on the excess pressure, closer to a rate "
            "cap than to a power law."
        )
    return text


def _band_note(post: dict) -> str:
    cover = post["coverage_90"]
    if cover <= 0.97:
        return ""
    sigma = post["parameters"]["sigma"]["mean"]
    return (
        f" The published law's 90 % band holds {cover:.2f} of the measured points, more than the 0.9 of a band "
        f"that describes its data: its sensor noise (σ {mm(sigma)} on average over the posterior) is inferred "
        "from the scored keyframes alone, and the band is also compared with the interpolated samples between "
        "them, which carry no noise of their own."
    )


def _loo_text(loo: dict) -> str:
    law = {"reference": "published law", "lockhart": "Lockhart law"}
    better = min(loo, key=lambda k: loo[k]["rank"])
    diff, dse = next(loo[k] for k in loo if k != better)["elpd_diff"], next(loo[k] for k in loo if k != better)["dse"]
    k_max = max(v["pareto_k_max"] for v in loo.values())
    verdict = "no preference between the laws" if diff < 2 * dse else f"in favour of the {law[better]}"
    return f"elpd difference {diff:.1f} ± {dse:.1f}: {verdict}; largest Pareto k̂ {k_max:.2f}" + (
        " (above 0.7: the estimate is unreliable)" if k_max > 0.7 else ""
    )


def calibration_section(c: dict) -> str:
    fit, ref, lock = c["fit"], c["posterior"]["reference"], c["posterior"]["lockhart"]
    ind = c["independent_noise_fit"]
    y_post = ref["parameters"]["Y"]
    draws = f"{c['chains']} × ({c['warmup']} + {c['samples']})"
    budget = sorted(fit["budget_sd_Pa"].items(), key=lambda kv: -kv[1])
    undetermined = sorted(
        {
            SYMBOLS.get(n, n)
            for d in c["fit_Y_ext_n"]["undetermined_directions"]
            for n, w in d["direction"].items()
            if abs(w) > 0.5
        }
    )
    ident = {k: v for k, v in ref["posterior_sd_over_prior_sd"].items() if k != "Y"}
    loo = c["loo"]
    hyper = c["likelihood"]["discrepancy"]
    rows = [
        (
            "fit of Y (published law), default likelihood",
            f"{pa(fit['estimate_Pa'])}, 90 % {pa_interval(*fit['interval_90_Pa'])} (width {pa(fit['width_Pa'])}); "
            f"RMSE {mm(fit['rmse_length_m'])}",
        ),
        (
            "NUTS, published law, " + draws,
            f"Y {pa(y_post['mean'])}, 90 % {pa_interval(*y_post['interval_90'])}; R-hat ≤ {ref['rhat_max']:.3f}, "
            f"{ref['divergences']} divergences; posterior sd ÷ prior sd "
            + ", ".join(f"{k} {v:.2f}" for k, v in ident.items()),
        ),
        (
            "width of the fit's 90 % interval of Y ÷ the posterior's",
            f"{c['fit_over_posterior_width_Y']:.2f} (target: within 25 %)",
        ),
        (
            "measured points inside the 90 % predictive band, this experiment replicated",
            f"{ref['coverage_90']:.2f} (published law), {lock['coverage_90']:.2f} (Lockhart)",
        ),
        (
            "the same, a new experiment's band",
            f"{ref['coverage_90_new_experiment']:.2f} (published law), "
            f"{lock['coverage_90_new_experiment']:.2f} (Lockhart)",
        ),
        (
            "fit of Y, ext, n",
            f"Y {pa(c['fit_Y_ext_n']['estimate'][Y])}; "
            + (
                f"{' and '.join(undetermined)} undetermined (the smallest eigenvalues of JᵀJ lie along them)"
                if undetermined
                else "every direction determined"
            ),
        ),
        (
            "NUTS, Lockhart law, " + draws,
            f"Y {pa(lock['parameters']['Y']['mean'])}, φ_L {1e3 * lock['parameters']['phi_L']['mean']:.2f} mm/s, "
            f"n_L {lock['parameters']['n_L']['mean']:.3f}; R-hat ≤ {lock['rhat_max']:.3f}, "
            f"{lock['divergences']} divergences",
        ),
        ("PSIS-LOO, Lockhart against published law", _loo_text(loo)),
        (
            "contrast: fit of Y under independent noise, the rig exact (`--discrepancy none`)",
            f"{pa(ind['estimate_Pa'])}, 90 % {pa_interval(*ind['interval_90_Pa'])} (width {pa(ind['width_Pa'])}, "
            f"1/{fit['width_Pa'] / ind['width_Pa']:.0f} of the default's); over-confident, see "
            "[Uncertainty](uncertainty.md)",
        ),
    ]
    budget_rows = [(BUDGET_NAMES.get(k, f"tolerance of `{k}`"), f"{v:.3g} Pa") for k, v in budget]
    lockhart_note = _lockhart_note(lock, c["likelihood"]["samples_used"]) + _band_note(ref)
    scored = c["likelihood"]["samples_used"]
    return (
        f"\n## Calibration\n\n`{c['command']}`: fast configuration, 0–{c['t_end_s']:g} s, forward drive, the "
        "default likelihood of `growjax fit` and `growjax posterior` (every row but the last): a Matérn-3/2 "
        "discrepancy, correlated sensor noise and the rig's default tolerance budget, the rig's errors inferred "
        f"([Uncertainty](uncertainty.md)). The public length trace is piecewise linear between keyframes, so the "
        f"likelihood scores its {scored} vertices and ends. At the fit's mode the discrepancy's amplitude is "
        f"{mm(hyper['amplitude_m'])} over {hyper['time_scale_s']:.2f} s and the noise {mm(hyper['noise_m'])}.\n\n"
        + table(("quantity", "value"), rows)
        + "\nThe fit's standard deviation of Y by source (their squares add up to its variance):\n\n"
        + table(("source", "sd of Y"), budget_rows)
        + f"\n{lockhart_note}\n"
    )


def discovery_section(d: dict) -> str:
    """``growjax discover mammobot``'s verdict, from ``paper.json``."""
    text = "\n## Missing physics\n\n`growjax discover mammobot` (the default likelihood) answers `" + d["effect"] + "`"
    effects = " and ".join(e.replace("_", " ") for e in d.get("effects") or [])
    if effects:
        text += f": {effects}, which lower the RMSE from {mm(d['rmse_before_m'])} to {mm(d['rmse_after_m'])}"
        if (d.get("misfit_after") or {}).get("structured"):
            text += "; the residuals still hold structure"
    elif d["effect"] == "none" and d.get("largest"):
        largest = d["largest"]
        text += (
            f": no effect of the catalogue clears the threshold (2ΔlogL > {d['threshold']:.2f}; the largest is "
            f"{largest['lr_statistic']:.2f}, {largest['effect'].replace('_', ' ')}), and the misfit of "
            f"{mm(d['rmse_before_m'])} is left to the discrepancy term"
        )
    return (
        text + ". How often discovery names a hidden effect, and how often it raises a false alarm, is measured on "
        "synthetic data on the [Benchmarks](benchmarks.md) page (`python benchmarks/discover.py`).\n"
    )


def render(results: Path = RESULTS) -> str:
    paper, calibration = (json.loads((results / name).read_text()) for name in ("paper.json", "calibration.json"))
    return (
        HEADER.format(environment=environment(paper, calibration))
        + paper_section(paper)
        + sensitivity_section(paper)
        + calibration_section(calibration)
        + discovery_section(paper["discover"])
    )


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", default=str(RESULTS))
    ap.add_argument("--out", default=str(REPO / "docs" / "results.md"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.write_text(render(Path(args.results)))
    print("wrote", out)
    return out


if __name__ == "__main__":
    main()
