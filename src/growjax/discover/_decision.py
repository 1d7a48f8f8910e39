"""The decision of a discovery: which candidates are confounded (with a base parameter or a rival effect), which
one is added, and the final answer."""

from __future__ import annotations

from growjax.model import effects as fx


def separated_by(name: str) -> str:
    """The measurement that tells the catalogue effect ``name`` from its neighbours (its class's ``separated_by``)."""
    cls = fx.CATALOGUE.get(name)
    return cls.separated_by if cls is not None else ""


def confounded_with_base(scores: dict) -> dict:
    """{candidate: its confounding record} of a round's ``scores`` that are confounded with a base parameter: the
    parameter it correlates with most, that correlation, its 2ΔlogL (base refitted and held) and what separates it."""
    out = {}
    for name, s in scores.items():
        if s["confounded"]:
            worst, c = max(s["correlation_with_base"].items(), key=lambda kv: abs(kv[1]), default=(None, 0.0))
            out[name] = {
                "parameter": worst,
                "correlation": c,
                "lr_statistic": s["lr_statistic"],
                "lr_statistic_base_held": s["lr_statistic_base_held"],
                "separate_by": separated_by(name),
            }
    return out


def choose(scores: dict, threshold: float, confounded: dict) -> str | None:
    """The candidate to add from a round's ``scores``: the one with the largest 2ΔlogL among those that clear
    ``threshold`` unconfounded; None when there is none, or when a rival that also clears it falls short of the best
    by less than ``threshold`` (the data do not tell them apart: both are then recorded in ``confounded``, each with
    its ``rival_effects``)."""
    clean = {n: s for n, s in scores.items() if s["clears_threshold"] and not s["confounded"]}
    if not clean:
        return None
    best = max(clean, key=lambda n: clean[n]["lr_statistic"])
    lr_best = scores[best]["lr_statistic"]
    rivals = [
        n for n, s in scores.items() if n != best and s["clears_threshold"] and s["lr_statistic"] > lr_best - threshold
    ]
    if not rivals:
        return best
    for name in (best, *rivals):  # another effect explains the data about as well: name neither
        others = [r for r in (best, *rivals) if r != name]
        confounded.setdefault(
            name,
            {
                "parameter": None,
                "correlation": None,
                "lr_statistic": scores[name]["lr_statistic"],
                "lr_statistic_base_held": scores[name]["lr_statistic_base_held"],
                "separate_by": separated_by(name),
            },
        )
        confounded[name]["rival_effects"] = others
    return None


def final_effect(added: list, misfit_after: dict, confounded: dict) -> str:
    """The answer: the first effect added if the misfit test then passes; ``"unexplained"`` where structure remains
    (after effects were added, or material with none added); ``"confounded"``; else ``"none"``."""
    if added and not misfit_after["structured"]:
        return added[0]
    if added:
        return "unexplained"  # candidates helped but structure remains: no catalogue effect is claimed
    if confounded:
        return "confounded"
    return "unexplained" if misfit_after["structured"] and misfit_after.get("material", True) else "none"
