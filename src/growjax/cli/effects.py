"""``growjax effects``: the effect catalogue: each effect's parameter, its range and what separates it from the
others."""

from __future__ import annotations

from growjax.cli import options
from growjax.cli.command import Process

NAME = "effects"
HELP = "list the effect catalogue: parameter, range, what separates each"
PROCESS = Process(workflow=False)


def add_arguments(parser) -> None:
    """``--json``."""
    options.json_option(parser)


def run(args) -> dict:
    """The catalogue, one row per effect."""
    from growjax.model.effects import CATALOGUE

    rows = []
    for name, cls in CATALOGUE.items():
        ((field, (lo, hi)),) = cls.ranges.items()
        rows.append(
            {
                "name": name,
                "parameter": f"{name}.{field}",
                "unit": cls.units.get(field, ""),
                "range": [lo, hi],
                "description": cls.description,
                "separated_by": cls.separated_by,
            }
        )
    return {"command": NAME, "effects": rows}


def summary_lines(s: dict) -> list[str]:
    """Three lines per effect: its description, parameter and range, what separates it."""
    lines = []
    for r in s["effects"]:
        lines.append(f"{r['name']}: {r['description']}")
        lines.append(f"    parameter {r['parameter']} in [{r['range'][0]:g}, {r['range'][1]:g}] {r['unit']}")
        lines.append(f"    separated by: {r['separated_by']}")
    return lines


__all__ = ["HELP", "NAME", "PROCESS", "add_arguments", "run", "summary_lines"]
