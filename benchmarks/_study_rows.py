"""The Benchmarks page's rows of the statistical studies: coverage, sets, populations, discovery and design."""

from __future__ import annotations

import numpy as np
from _rows import Row, at_least, at_most, info, ratio, s, within


def share(x) -> str:
    return f"{float(x):.2f}"


# -- coverage and uncertainty --------------------------------------------------------------------------------------


def coverage(r: dict) -> list[Row]:
    rows = [
        within(f"Y's 90 % interval covers the truth, {group} data ({g['sets']} sets)", g["coverage_90"], 0.80, 0.97)
        for group, g in r["summary"].items()
    ]
    width = r["summary"].get("none", {}).get("width_ratio_vs_independent")
    if width:
        rows.append(
            at_most("interval width ÷ the independent-noise one, white-noise data", width["median"], 1.5, ratio)
        )
    return rows


def rig_agreement(r: dict) -> list[Row]:
    rows = []
    for group, g in r["summary"].items():
        rows.append(
            within(
                f"fit's 90 % interval of Y covers the truth, rig {group}", g["fit_inferred"]["coverage_90"], 0.80, 0.97
            )
        )
        if "posterior" in g:
            w = g["width_ratio_fit_over_posterior"]["median"]
            rows.append(within(f"fit's interval width ÷ the posterior's, rig {group}", w, 0.75, 1.25))
            rows.append(
                within(
                    f"measured points inside the posterior's 90 % band, rig {group}",
                    g["posterior"]["band_coverage_90"],
                    0.85,
                    0.95,
                )
            )
    return rows


def windows(r: dict) -> list[Row]:
    worst: dict[str, float] = {}
    for pair in r["pairs"]:
        worst[pair["likelihood"]] = max(worst.get(pair["likelihood"], 0.0), pair["z"])
    fmt = lambda v: f"{v:.2f} se"  # noqa: E731
    why = {"independent": "above the target: independent noise leaves out the model's error, which the windows show"}
    rows = [
        at_most(
            f"largest |ΔY| between disjoint windows, {k} likelihood", v, 2.0, fmt, why=why.get(k, "above the target")
        )
        for k, v in worst.items()
    ]
    rows.append(at_most("0–10 s interval of Y, share of the 5–15 kPa box", r["interval_share_of_box"], 0.33, share))
    return rows


def predict(r: dict) -> list[Row]:
    return [
        within(f"held-out 7–10 s points inside the 90 % band, {k}", v["coverage_90_after_split"], 0.80, 0.97)
        for k, v in r.items()
        if isinstance(v, dict) and "coverage_90_after_split" in v
    ]


# -- sets and populations ------------------------------------------------------------------------------------------


def sets(r: dict) -> list[Row]:
    sm = r["summary"]
    return [
        within(
            f"joint fit's 90 % interval of Y covers the truth ({sm['sets']} sets)",
            sm["joint"]["coverage_90"],
            0.80,
            0.97,
        ),
        at_least(
            "joint interval narrower than the best single experiment's",
            sm["joint_narrower_than_best_single"],
            0.90,
            share,
        ),
        info("rig errors taken per experiment: coverage", share(sm["joint_independent_rig"]["coverage_90"])),
    ]


def mixed_set(r: dict) -> list[Row]:
    (lf, hf), (ls, hs) = r["forward"]["interval_90_Pa"], r["stepper"]["interval_90_Pa"]
    overlap = max(lf, ls) <= min(hf, hs)
    lo, hi = r["joint"]["interval_90_Pa"]
    return [
        Row("forward and stepper experiments' intervals of Y overlap", "yes" if overlap else "no", "yes", overlap),
        info(f"joint Y (truth {r['truth_Pa']:.0f} Pa)", f"{r['joint']['estimate_Pa']:.0f} Pa [{lo:.0f}, {hi:.0f}]"),
    ]


def population(r: dict) -> list[Row]:
    sm = r["summary"]
    n = f"{sm['populations']} populations"
    return [
        within(f"population median's 90 % interval covers the truth ({n})", sm["median_coverage_90"], 0.80, 0.97),
        within(f"population spread's 90 % interval covers the truth ({n})", sm["spread_coverage_90"], 0.80, 0.97),
        within("a held-out robot's points inside its 90 % predictive band", sm["new_robot_band_coverage"], 0.80, 0.97),
        at_most("NUTS, 4 × (500 + 500), median", sm["median_nuts_s"], 900, s, timed=True),
    ]


# -- discovery -----------------------------------------------------------------------------------------------------


def discover(r: dict) -> list[Row]:
    hidden = [x for x in r["runs"] if x["effect"] is not None]
    clean = [x for x in r["runs"] if x["effect"] is None]
    named = sum(x["named"] for x in hidden)
    rows = [info(f"hidden effect named ({len(r['named_share_per_effect'])} effects)", f"{named} of {len(hidden)}")]
    if clean:
        wrong = sum(x["found"] != "none" for x in clean)
        rows.append(
            Row("false positives on clean data", f"{wrong} of {len(clean)}", "≤ 1 of 20", wrong <= len(clean) / 20)
        )
    rows.append(info("a wrong effect claimed, share of hidden-effect runs", share(r["wrong_effect_share"])))
    rows.append(info("median wall time of a run", s(r["median_wall_s"])))
    if r.get("wall_ratio_to_independent"):
        rows.append(
            at_most("wall time ÷ under independent noise", r["wall_ratio_to_independent"], 1.5, ratio, timed=True)
        )
    return rows


def discover_discrepancy(r: dict) -> list[Row]:
    ok = r["none"] >= 0.95 * r["sets"]
    return [
        Row(
            "answer `none` on data with a discrepancy and no effect",
            f"{r['none']} of {r['sets']}",
            "≥ 19 of 20",
            ok,
            "" if ok else "an effect claimed",
        )
    ]


# -- design --------------------------------------------------------------------------------------------------------


def design(r: dict) -> list[Row]:
    land, rep = r["landscape"], r["replications"]
    beats = bool(land["design_beats_best_random"])
    rows = [
        Row(
            f"design's criterion beats the best of {land['random_admissible']} random inputs",
            f"{land['design_criterion']:.3f} against {land['random_best_criterion']:.3f}",
            "lower",
            beats,
            "" if beats else "a random input scored lower",
        )
    ]
    for name, g in rep.get("design", {}).items():
        if g.get("realised_sd_log") is not None:
            rows.append(
                within(f"realised ÷ predicted sd of ln {name}, design", g["realised_over_predicted"], 0.75, 1.25)
            )
            rows.append(within(f"90 % intervals of {name} cover the truth, design", g["coverage_90"], 0.80, 0.97))
    for name, x in rep.get("design_over_published_realised_sd", {}).items():
        if x is not None:
            rows.append(at_most(f"realised sd of ln {name}, design ÷ published pulse train", x, 0.5, ratio))
    return rows


def design_discrimination(r: dict) -> list[Row]:
    rows = []
    for label, rates in r["named_rate"].items():
        for effect, rate in rates.items():
            what = "no effect named on clean data" if effect == "none" else f"{effect} named when hidden"
            rows.append(at_least(f"{label}: {what}", rate, 0.9, share))
    return rows


def design_lockhart(r: dict) -> list[Row]:
    """The design's rows, and the growth-law parameters' median 90 % interval as a share of the prior box."""
    import growjax as gj
    from growjax.calibration import default_range

    rows = design(r)
    base = gj.reference(growth_law=r["arguments"].get("growth_law", "reference"))
    fits = [x["design"] for x in r.get("rows", []) if x.get("design", {}).get("status") in ("converged", "max_steps")]
    for name in ("robot.lockhart_rate", "robot.lockhart_exponent"):
        if not fits or name not in fits[0]:
            continue
        lo, hi = default_range(base, name)
        widths = [
            np.log(f[name]["interval_90"][1] / f[name]["interval_90"][0]) if f[name]["interval_90"] else np.inf
            for f in fits
        ]
        rows.append(
            at_most(
                f"{name}: 90 % interval ÷ its prior box (ln widths), median",
                np.median(widths) / np.log(hi / lo),
                0.33,
                share,
            )
        )
    return rows
