"""``growjax params``: the parameters of a drive's published set: names, symbols, defaults, units, physical
ranges."""

from __future__ import annotations

import re

import numpy as np

from growjax.cli import options
from growjax.cli.command import Process

NAME = "params"
HELP = "list the parameters: names, symbols, defaults, units, physical ranges"
PROCESS = Process(workflow=False)
OPTIONS = (options.DRIVE,)


def add_arguments(parser) -> None:
    """``--drive`` (whose published set) and ``--json``."""
    options.add(parser, OPTIONS)
    options.json_option(parser)


def run(args) -> dict:
    """The table: one row per scalar parameter of ``--drive``'s reference."""
    import growjax as gj
    from growjax.model import params as gp

    base = gj.reference(args.drive)
    symbols = {q: s for s, q in gp.ALIASES.items() if s not in ("phi",)}
    ranges = gp.physical_ranges(base)
    rows = []
    for q in gp.parameter_names(base):
        block, field = q.split(".")
        value = gp.get(base, q)
        if value is None or np.ndim(value) != 0:
            continue
        cls = type(getattr(base, block))
        about = _attribute_text(cls.__doc__ or "", field)
        lo, hi, unit = ranges.get(q, (None, None, ""))
        unit = unit or _unit_of(about)
        rows.append(
            {
                "name": q,
                "symbol": symbols.get(q, ""),
                "value": float(value),
                "unit": unit,
                "range": None if lo is None else [lo, hi],
                "description": about,
            }
        )
    return {"command": NAME, "drive": args.drive, "parameters": rows}


def _attribute_text(doc: str, field: str) -> str:
    """The description of ``field`` in a Google-style ``Attributes:`` section (one line), or ''."""
    flat = " ".join(doc.split("Attributes:", 1)[-1].split())
    m = re.search(rf"(?:^|[\s.:]){re.escape(field)}: (.*?)(?=\s+[a-z_]+: |$)", flat)
    return m.group(1).strip() if m else ""


def _unit_of(description: str) -> str:
    """The SI unit a docstring states at the end of a parameter's description ("..., kg/m³.", "... (–)."), or ''."""
    text = re.sub(r"\s*\((?![^()]*/)[^()]*\)\.?$", "", description.strip()).rstrip(". ")  # drop a closing remark
    if "(–)" in description and not re.search(r",\s*\S+$", text):
        return "-"
    last = text.rsplit(", ", 1)[-1] if ", " in text else text
    last = last.split(":")[0].split(";")[0].strip()
    if (
        last
        and " " not in last
        and len(last) <= 16
        and (not last.isalpha() or last in ("m", "s", "N", "Pa", "kg", "V", "A", "H", "rad", "Hz", "Ω"))
    ):
        return last
    return "-" if "(–)" in description else ""


def summary_lines(s: dict) -> list[str]:
    """The table, one parameter a line."""
    lines = [f"{'name':34s} {'symbol':7s} {'value':>12s} {'unit':16s} {'physical range':24s} description"]
    for r in s["parameters"]:
        rng = "" if r["range"] is None else f"{r['range'][0]:g} – {r['range'][1]:g}"
        lines.append(
            f"{r['name']:34s} {r['symbol']:7s} {r['value']:12.5g} {r['unit']:16s} {rng:24s} {r['description'][:70]}"
        )
    return lines


__all__ = ["HELP", "NAME", "OPTIONS", "PROCESS", "add_arguments", "run", "summary_lines"]
