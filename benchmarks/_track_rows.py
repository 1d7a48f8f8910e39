"""The Benchmarks page's rows of the tracking studies: accuracy, coverage and cost of the filter, change detection,
output feedback and the public experiment's demand."""

from __future__ import annotations

import numpy as np
from _rows import Row, at_most, info, ms, s, within

RIGS, DRIFT, SEEDS, CLEAN, FEEDBACK = 20, 1, 10, 10, 10  # the sizes the targets are set for


def mm(x) -> str:
    return f"{1e3 * float(x):.3f} mm"


def of(k: int, n: int) -> str:
    return f"{int(k)} of {int(n)}"


def sized(row: Row, n: int, wanted: int, what: str) -> Row:
    """``row`` with its reason naming a smaller study than the target's."""
    if n >= wanted or row.met is not False:
        return row
    return Row(row.measured, row.value, row.target, row.met, f"{row.why}; {n} {what}, not {wanted}", row.timed)


def count_at_least(measured: str, k: int, n: int, share: float, why: str) -> Row:
    """``k`` of ``n`` against a target of a ``share`` of them."""
    need = -(-round(1000 * share * n) // 1000)
    return Row(measured, of(k, n), f"≥ {of(need, n)}", k >= need, "" if k >= need else why)


def rig_rows(m: dict, label: str) -> list[Row]:
    """The accuracy and coverage rows of one study's summary (``m``: a method's results)."""
    sm = m["summary"]
    rigs = [r for r in m["rigs"] if "failed" not in r]
    n, tracked = sm["records"], len(rigs)
    inside = sum(0.80 <= r["coverage_90"] <= 0.97 for r in rigs)
    worst = max(rigs, key=lambda r: r["rmse_m"])
    rows = [
        sized(
            at_most(
                f"length RMSE from pressure and syringe, 10 s, {label}: worst of {tracked} rigs tracked",
                sm["rmse_worst_m"],
                5e-4,
                mm,
                why=f"{worst['record']}; mean {mm(sm['rmse_mean_m'])}",
            ),
            n,
            RIGS,
            "rigs",
        ),
        sized(
            within(
                f"share of samples inside the 90 % length band, {label}: mean of {tracked} rigs tracked",
                sm["coverage_mean"],
                0.80,
                0.97,
            ),
            n,
            RIGS,
            "rigs",
        ),
        info(
            f"rigs whose 90 % length band covers 0.80–0.97 of their samples, {label} (lowest share)",
            f"{of(inside, tracked)} ({sm['coverage_min']:.2f})",
        ),
        info(f"innovations' NIS per reading, {label} (1 when honest)", f"{sm['nis_per_reading_mean']:.2f}"),
    ]
    failed = sm.get("failed") or []
    if failed:
        rows.insert(
            0,
            Row(
                f"rigs whose track failed, {label}",
                f"{of(len(failed), n)} ({', '.join(failed)})",
                "none",
                False,
                "the filter failed at a sharp switch of the fast model",
            ),
        )
    return rows


def drift_rows(m: dict, label: str) -> list[Row]:
    d = m.get("drift_summary")
    if not d:
        return []
    n = d["records"]
    if "coverage_min" not in d:
        why = "the filter diverged after a sharp switch of the fast model"
        return [Row(f"Y +10 % over 60 s, {label}: records tracked", of(0, n), f"{n} of {n}", False, why)]
    return [
        sized(
            within(
                f"Y +10 % over 60 s ({n} records), {label}: share of samples inside the 90 % length band, mean",
                d["coverage_mean"],
                0.80,
                0.97,
            ),
            n,
            DRIFT,
            "records",
        ),
        info(
            f"Y +10 % over 60 s, {label}: share inside the band, lowest and highest record",
            f"{d['coverage_min']:.2f}, {d['coverage_max']:.2f}",
        ),
        info(f"Y +10 % over 60 s, {label}: length RMSE, worst", mm(d["rmse_worst_m"])),
        info(
            f"Y +10 % over 60 s, {label}: share of samples whose Y band covers the true Y",
            f"{d['y_coverage_mean']:.2f}",
        ),
    ]


def track(r: dict) -> list[Row]:
    rows = []
    for name, m in r["methods"].items():
        rows += rig_rows(m, name) + drift_rows(m, name)
        sm = m["summary"]
        base = r["baseline"]["step_median_s"]
        why = f"above the target, at {sm['step_median_s'] / base:.1f}× `simulate_from` alone ({ms(base)} here)"
        rows.append(
            at_most(f"filter step per 10 ms sample, {name}, median", sm["step_median_s"], 1e-3, ms, why=why, timed=True)
        )
        rows.append(info(f"filter step, {name}, 90th percentile", ms(sm["step_p90_s"])))
        if "smooth_10s_s" in m:
            rows.append(at_most(f"10 s record tracked and smoothed, {name}", m["smooth_10s_s"], 5.0, s, timed=True))
    rows.append(info("`simulate_from` over the same 10 ms, median", ms(r["baseline"]["step_median_s"])))
    return rows


def track_walk(r: dict) -> list[Row]:
    """Y's random walk set faster than the default: what the drift records gain, what the still rigs pay."""
    q = r.get("walk")
    rows = []
    for name, m in r["methods"].items():
        sm, d = m["summary"], m.get("drift_summary") or {}
        label = f"Y's walk {100 * q:.0f} %/√s, {name}"
        rows.append(info(f"{label}: length RMSE, worst of {sm['records']} still rigs", mm(sm["rmse_worst_m"])))
        if "coverage_mean" in d:
            rows.append(
                info(f"{label}, Y +10 % over 60 s: share inside the length band, mean", f"{d['coverage_mean']:.2f}")
            )
            rows.append(
                info(f"{label}, Y +10 % over 60 s: share whose Y band covers the true Y", f"{d['y_coverage_mean']:.2f}")
            )
    return rows


def track_change(r: dict) -> list[Row]:
    rows = []
    for kind, label in (("leak", "a leak opening"), ("tip", "the tip loaded")):
        c = r.get("change", {}).get(kind)
        if not c:
            continue
        n = c["seeds"]
        failed = c.get("failed") or []
        late = f"the track failed on {', '.join(failed)}" if failed else f"median delay {c['delay_s_median']:.2f} s"
        rows.append(
            sized(
                count_at_least(f"{label}: flagged within 0.5 s", c["flagged_within_0.5_s"], n, 0.9, late),
                n,
                SEEDS,
                "seeds",
            )
        )
        rows.append(
            sized(
                count_at_least(
                    f"{label}: named right", c["named_right"], n, 0.8, late if failed else "named otherwise"
                ),
                n,
                SEEDS,
                "seeds",
            )
        )
    clean = r.get("change", {}).get("clean")
    if clean:
        k, n = clean["records_flagged"], clean["records"]
        why = f"largest statistic {clean['max_statistic']:.1f} sd against a threshold of {clean['threshold']:g}"
        value = of(k, n)
        dismissed = clean.get("records_with_dismissed_flags", 0)
        if dismissed:  # flags whose named effect was below a tenth of its typical size
            value += f" ({dismissed} with a flag dismissed as too small to be a change)"
        rows.append(
            sized(Row("clean 60 s records flagged", value, "none", k == 0, "" if k == 0 else why), n, CLEAN, "records")
        )
    failed = [name for c in r.get("change", {}).values() for name in c.get("failed", [])]
    if failed:
        why = "the filter diverged after a sharp switch of the fast model"
        rows.append(Row("watched records whose track failed", ", ".join(failed), "none", False, why))
    fb = r.get("feedback")
    if fb:
        rows += feedback_rows(fb)
    return rows


def feedback_rows(fb: dict) -> list[Row]:
    n = len(fb["rows"])
    crossed = sum(bool(x.get("limit_crossed")) for x in fb["rows"])
    failed = fb.get("failed") or []
    if len(failed) == n:
        return [Row("output feedback: rigs whose estimator failed", of(n, n), "none", False, "every run failed")]
    lost = [Row("output feedback: rigs whose estimator failed", of(len(failed), n), "none", False)] if failed else []
    share = float(np.mean([r.get("estimate_coverage_90", 0.0) for r in fb["rows"] if "failed" not in r]))
    return lost + [
        sized(
            at_most(
                f"output feedback, reference plant: length RMSE, worst of {n} rigs",
                fb["rmse_m_max"],
                1e-3,
                mm,
                why="the estimate's error: the rig's estimated errors settle away from the truth",
            ),
            n,
            FEEDBACK,
            "rigs",
        ),
        Row("output feedback: rigs whose membrane limit was crossed", of(crossed, n), "none", crossed == 0),
        info("output feedback: length RMSE, median", mm(fb["rmse_m_median"])),
        info(
            "output feedback: rigs whose estimate's 90 % band holds ≥ 0.8 of the samples",
            of(sum(r.get("estimate_coverage_90", 0.0) >= 0.8 for r in fb["rows"] if "failed" not in r), n),
        ),
        info("output feedback: share of samples inside the estimate's 90 % band, mean of rigs", f"{share:.2f}"),
    ]


def track_feedback(r: dict) -> list[Row]:
    return feedback_rows(r["feedback"])


def track_public(r: dict) -> list[Row]:
    sm, fl = r["smoothed"], r["filtered"]
    return [
        Row(
            "public experiment: the demand estimated from the length, its band and the published pulse train drawn "
            "together",
            f"`{r['figure']}`",
            "a figure",
            bool(r.get("figure")),
        ),
        info(
            "published pulse train inside the demand's 90 % band, smoothed (filtered), away from edges",
            f"{sm['coverage_90_away_from_edges']:.2f} ({fl['coverage_90_away_from_edges']:.2f})",
        ),
        info(
            "estimated demand's mean on the pulses (published 150 kPa) and its band's median width, smoothed",
            f"{1e-3 * sm['on_mean_Pa']:.0f} kPa; {1e-3 * sm['band_width_median_Pa']:.0f} kPa",
        ),
    ]


def start_transient(r: dict) -> list[Row]:
    """The fast configuration's length against the reference's when the demand rises at the start of a run."""
    return [
        info(f"fast − reference length, {x['demand']}, RMS over {r['t_end_s']:.0f} s", mm(x["rms_m"]))
        for x in r["rows"]
    ]
