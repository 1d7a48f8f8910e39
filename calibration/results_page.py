"""Write docs/results.md, the public MAMMOBOT experiment's results, from the results files in calibration/results/.

Run from the repository root::

    python calibration/results_page.py [--results calibration/results] [--out docs/results.md]
    python calibration/results_page.py --copy-benchmarks [--benchmarks docs/benchmarks.md]

The files, each written by the script named in it (with the machine and versions it ran on):

- ``paper.json``: ``python calibration/paper_public.py`` (simulations, the 500-set sweep, Sobol indices);
- ``calibration.json``: ``python calibration/calibrate_public.py`` (fits and posteriors under the default
  likelihood, LOO, the independent-noise contrast);
- ``benchmarks.json``: the rows of the discovery and control sections of the Benchmarks page, copied from
  ``docs/benchmarks.md`` (which ``python benchmarks/report.py`` writes) by ``--copy-benchmarks``;
- ``calibration/discover_public/discover.json``: ``growjax discover mammobot`` (its ``--json``).

The page is regenerated from the files alone: rerun a script, then this one, never edit the page.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "calibration" / "results"
DISCOVER_PUBLIC = REPO / "calibration" / "discover_public" / "discover.json"
Y = "robot.yield_pressure"
SYMBOLS = {Y: "Y", "robot.growth_exponent": "n", "robot.extensibility": "ext"}
# The Benchmarks page's sections the page quotes, and the command that makes each.
COPIED = {
    "discover": "python benchmarks/discover.py --factors 1 --baseline 3",
    "discover_rig_known": "python benchmarks/discover.py --effects retraction_folding trapped_air --factors 1 "
    "--clean 5 --tolerance none --out benchmarks/results/discover_rig_known.json",
    "discover_folding_no_catheter_tolerance": "python benchmarks/discover.py --effects retraction_folding --factors 1 "
    "--clean 0 --tolerance robot.catheter_friction=0 "
    "--out benchmarks/results/discover_folding_no_catheter_tolerance.json",
    "discover_folding_twofold": "python benchmarks/discover.py --effects retraction_folding --factors 2 --clean 0 "
    "--out benchmarks/results/discover_folding_twofold.json",
    "control": "python benchmarks/control.py",
}
CONTROL_NAMES = {
    "forward open-loop profile": "optimised open-loop pressure-demand profile",
    "forward feedback (length PID)": "tuned length PID over the pressure loop",
    "forward MPC": "MPC on the fast model",
    "inverse feedback (step controller)": "stepper, closed-loop full-step controller",
    "inverse feedback, 1/16 microstep": "stepper, 1/16 microstepping",
}
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
    "fast_model_error": "fast configuration's error",
}

HEADER = """# Results on the public experiment

This page is written by `python calibration/results_page.py` from the results files in `calibration/results/`
(and `calibration/discover_public/discover.json`); each section names the command that makes its numbers.
The MAMMOBOT experiment the paper validates against (10 s of robot length at 100 Hz with the catheter
length, forward drive; not shipped with growjax, the commands read it as `mammobot`, see
[Bring your own data](data.md#the-public-mammobot-experiment)). Lengths are RMSE over 0–10 s unless said otherwise.
"""

STEPPER = """
The stepper model cannot follow the length more closely than its step grid: one full motor step moves
the syringes 40 µm, 3.1 mm of robot length, and the shipped counter issues a step only when the sampled
demand is half a step away, which the retractions of the sawtooth never reach. The rate of that counter
is not given for the rig; over 1–100 Hz its own tracking error is smallest at 3 Hz, the value growjax
uses (`python benchmarks/controller_rate.py`).
"""

ABOUT_LENGTH = """
## About the measured length

The public length trace is piecewise linear between about 17 vertices over 10 s: it was digitised at key
frames and interpolated to 100 Hz. Its 1 000 samples therefore carry far less independent information than
their number suggests, which any likelihood on them (and any interval it gives) has to take into account{scored}
"""


# -- formatting ------------------------------------------------------------------------------------------------


def mm(x) -> str:
    return f"{1e3 * float(x):.2f} mm"


def pa(x) -> str:
    return f"{float(x):.0f} Pa"


def pa_interval(lo, hi) -> str:
    return f"{float(lo):.0f}–{float(hi):.0f} Pa"


def environment_line(r: dict) -> str:
    env = r["environment"]
    return (
        f"Run on {env['machine']} ({env['device']}); Python {env['python']}, jax {env['jax']}, "
        f"growjax {env['growjax']}."
    )


def table(head: tuple, rows: list) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def count(text: str) -> tuple[int, int]:
    """(k, n) of a benchmark value "k of n"."""
    k, n = re.fullmatch(r"(\d+) of (\d+)", text.strip()).groups()
    return int(k), int(n)


# -- sections --------------------------------------------------------------------------------------------------


def paper_section(p: dict) -> str:
    best = p["sweep_best"]
    rows = [
        (
            "forward model (PID, ideal torque sources), published parameters",
            mm(p["forward_rmse_m"]),
            "1.7 mm",
            f"`{p['commands']['forward']['command']}`",
        ),
        (
            'stepper ("inverse") model with the shipped step controller at 3 Hz',
            mm(p["stepper_rmse_m"]),
            "2.5 mm",
            f"`{p['commands']['stepper']['command']}`",
        ),
        (
            f"best set of the paper's {p['sweep_n']}-set Latin hypercube",
            f"Y = {best['parameters'][Y] / 1e3:.2f} kPa, {1e3 * best['rmse_length_m']:.3f} mm",
            "Y ≈ 7.9 kPa, 1.7 mm",
            "`growjax sweep mammobot`",
        ),
        (
            "safe pressure of the membrane, 2tσ_y/(r_o·SF)",
            f"{p['pressure_limit_Pa'] / 1e3:.1f} kPa",
            "373.3 kPa",
            "`growjax params`, `gj.pressure_limit`",
        ),
    ]
    return (
        f"\n## Against the paper\n\n`python calibration/paper_public.py` runs the commands below. "
        f"{environment_line(p)}\n\n" + table(("quantity", "growjax", "paper", "how"), rows) + STEPPER
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
        f"\n## Sensitivity\n\nSobol indices over the paper's box ({box}; {sob['n_runs']} runs, "
        f"`growjax sweep mammobot --sobol`, run by the same script): {'; '.join(parts)}; {tail}. In the published "
        "growth law the velocity term is about 1e-10 of the other forces on the rod, so nothing in the length "
        "depends on n and ext.\n"
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
    tolerances = ", ".join(f"`{k}` {100 * v:.0f} %" for k, v in c["likelihood"]["tolerances"].items())
    return (
        f"\n## Calibration\n\nFast configuration, 0–{c['t_end_s']:g} s, forward drive (`{c['command']}`). "
        f"{environment_line(c)} Every row but the last uses the default likelihood of `growjax fit` and "
        "`growjax posterior`: the model plus a Matérn-3/2 discrepancy plus sensor noise, with the rig's tolerances "
        f"({tolerances}) as priors on its errors, inferred from the data ({c['likelihood']['samples_used']} scored "
        f"samples; at the fit's mode the discrepancy's amplitude is {mm(hyper['amplitude_m'])}, its time scale "
        f"{hyper['time_scale_s']:.2f} s, the noise {mm(hyper['noise_m'])}).\n\n"
        + table(("quantity", "value"), rows)
        + "\nThe fit's standard deviation of Y by source (their squares add up to its variance):\n\n"
        + table(("source", "sd of Y"), budget_rows)
        + f"\n{lockhart_note}\n"
    )


def discovery_section(b: dict, public: dict | None) -> str:
    main = b["discover"]
    rows = {r[0]: r for r in main["rows"]}
    named = {}
    for r in main["rows"]:
        m = re.fullmatch(r"`(\w+)` named", r[0])
        if m:
            k, n = count(r[1])
            conf = int(re.match(r"(\d+)", r[2]).group(1)) if r[2] else 0
            named[m.group(1)] = (k, n, conf)
    full = sorted(e for e, (k, n, c) in named.items() if k == n)
    rest = {e: v for e, v in named.items() if e not in full}
    fp_k, fp_n = count(rows["false positives on clean data"][1])

    def phrase(e, k, n, conf):
        return f"`{e}` {k} of {n}" + (f" ({conf} `confounded`)" if conf else "")

    def named_in(section, effect):
        r = next(r for r in b[section]["rows"] if r[0] == f"`{effect}` named")
        return r[1]

    text = (
        f"\n## Discovery\n\nOn synthetic data with one hidden effect at a moderate magnitude (made by the reference "
        f"configuration, 0.2 mm noise, ten seeds per effect; `{COPIED['discover']}`), `discover` under its default "
        f"likelihood names {', '.join(f'`{e}`' for e in full)} in every seed, and "
        f"{'; '.join(phrase(e, *v) for e, v in rest.items())}. "
        + (
            "It never claims a wrong effect"
            if float(rows["a wrong effect claimed"][1]) == 0
            else f"It claims a wrong effect in a share {rows['a wrong effect claimed'][1]} of the hidden-effect runs"
        )
        + f", and raises {fp_k} false alarms on {fp_n} data sets without a hidden effect. A run's median wall time "
        f"is {rows['median wall time of a run'][1]}"
        + (
            f", {rows['wall time against independent noise'][1]}× that under `--discrepancy none`"
            if "wall time against independent noise" in rows
            else ""
        )
        + f" ({environment_line_copied(main)}).\n\n"
        "An effect whose trace the rig's tolerances (chiefly the catheter friction's 20 %) or a base parameter can "
        "imitate is hard to name from the length alone: the data then favour it by less than the threshold. For "
        "the retraction folding: with the rig taken as known (`tolerances={}`; "
        f"`{COPIED['discover_rig_known']}`) it is named in {named_in('discover_rig_known', 'retraction_folding')} "
        f"seeds and trapped air in {named_in('discover_rig_known', 'trapped_air')}; with only the catheter friction's "
        f"tolerance set to zero (`{COPIED['discover_folding_no_catheter_tolerance']}`) in "
        f"{named_in('discover_folding_no_catheter_tolerance', 'retraction_folding')}; at twice the magnitude, with the "
        f"default tolerances (`{COPIED['discover_folding_twofold']}`), in "
        f"{named_in('discover_folding_twofold', 'retraction_folding')}. A researcher who has measured the frictions "
        "should say so with `--tolerance`; otherwise the `confounded` answer, with its separating measurement, is "
        "what these data support.\n"
    )
    if public:
        text += public_discovery(public)
    return text


def public_discovery(d: dict) -> str:
    """The sentence on ``growjax discover mammobot``'s verdict (its ``--json``)."""
    head = (
        "\nOn the public experiment (`growjax discover mammobot --json calibration/discover_public/discover.json "
        f"--out calibration/discover_public`, under the default likelihood) the verdict is `{d['effect']}`"
    )
    effects = " and ".join(e.replace("_", " ") for e in d.get("effects", []))
    if effects:
        head += f": {effects} lower the RMSE from {mm(d['rmse_before_m'])} to {mm(d['rmse_after_m'])}" + (
            ", but the misfit test still finds structure in the residuals"
            if d.get("misfit_after", {}).get("structured")
            else ""
        )
    first = d["evidence"][0] if d.get("evidence") else {}
    if d["effect"] == "none" and first:
        best = max(first, key=lambda k: first[k]["lr_statistic"])
        head += (
            f": no catalogue effect clears the threshold (2ΔlogL > {d['threshold']:.2f}; the largest is "
            f"{first[best]['lr_statistic']:.2f}, {best.replace('_', ' ')}), and the misfit of "
            f"{mm(d['rmse_before_m'])} is left to the discrepancy term"
        )
    return head + ".\n"


def environment_line_copied(section: dict) -> str:
    return "the benchmark's record: " + re.sub(r"; run \d{4}-\d{2}-\d{2}", "", section["environment"])


def control_section(b: dict, limit_pa: float) -> str:
    ctl = b["control"]
    rows, peaks = [], []
    for name, value, note in ctl["rows"]:
        m = re.match(r"peak (\d+) kPa, evaluated on the (\w+) configuration", note)
        if not m or name not in CONTROL_NAMES:
            continue
        peaks.append(float(m.group(1)))
        rows.append((CONTROL_NAMES[name], value, f"{m.group(1)} kPa"))
    rows.append(("paper, stepper model", "2.5 mm", "–"))
    crossed = max(peaks) >= limit_pa / 1e3
    return (
        f"\n## Control\n\nDesigned on the fast configuration, evaluated on the reference one, 0–10 s of the "
        f"measured length as the target (`{COPIED['control']}`; {environment_line_copied(ctl)}):\n\n"
        + table(("design", "length RMSE", "peak pressure"), rows)
        + ("\nA design crosses" if crossed else "\nNo design crosses")
        + f" the membrane limit ({limit_pa / 1e3:.1f} kPa). Full steps place the robot on a 3.1 mm grid, so a "
        "full-step controller cannot do much better than 3.1/√12 ≈ 0.9 mm; microstepping removes the grid.\n"
    )


def render(results: Path = RESULTS, discover_public: Path = DISCOVER_PUBLIC) -> str:
    read = lambda name: json.loads((results / name).read_text())  # noqa: E731
    paper, calibration, benchmarks = read("paper.json"), read("calibration.json"), read("benchmarks.json")
    public = json.loads(discover_public.read_text()) if discover_public.exists() else None
    return (
        HEADER
        + paper_section(paper)
        + sensitivity_section(paper)
        + calibration_section(calibration)
        + discovery_section(benchmarks, public)
        + control_section(benchmarks, paper["pressure_limit_Pa"])
        + ABOUT_LENGTH.format(scored=_scored(calibration))
    )


def _scored(c: dict) -> str:
    used, window = c["likelihood"]["samples_used"], c["t_end_s"]
    if used >= 100 * window:
        return ". The calibration above scores every sample."
    return (
        f": the calibration above scores the {used} samples at its vertices and ends "
        "(see [Uncertainty](uncertainty.md#the-likelihood))."
    )


def copy_benchmarks(page: Path, results: Path = RESULTS) -> Path:
    """benchmarks.json: the rows of the sections :data:`COPIED` of the Benchmarks page, as it shows them."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from report import sections, table_rows

    found = sections(page.read_text())
    missing = [k for k in COPIED if k not in found]
    if missing:
        raise SystemExit(f"{page} has no section {', '.join(missing)}")
    copied = {}
    for name, command in COPIED.items():
        text = found[name]
        copied[name] = {"command": command, "environment": text.split("\n\n")[1].strip(), "rows": table_rows(text)}
    out = results / "benchmarks.json"
    out.write_text(
        json.dumps(
            {"source": "docs/benchmarks.md (python benchmarks/report.py)", **copied}, indent=1, ensure_ascii=False
        )
        + "\n"
    )
    return out


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", default=str(RESULTS))
    ap.add_argument("--out", default=str(REPO / "docs" / "results.md"))
    ap.add_argument(
        "--copy-benchmarks",
        action="store_true",
        help="first copy the discovery and control rows of --benchmarks into the results folder",
    )
    ap.add_argument("--benchmarks", default=str(REPO / "docs" / "benchmarks.md"))
    args = ap.parse_args(argv)
    if args.copy_benchmarks:
        print("wrote", copy_benchmarks(Path(args.benchmarks), Path(args.results)))
    out = Path(args.out)
    out.write_text(render(Path(args.results)))
    print("wrote", out)
    return out


if __name__ == "__main__":
    main()
