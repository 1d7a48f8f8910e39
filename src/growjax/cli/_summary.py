"""What the commands' summaries for people share: values in mm and kPa, where the fixed parameters came from, and
the data's name."""

from __future__ import annotations

from pathlib import Path


def kpa(x) -> str:
    """A pressure, Pa, in kPa ('–' for None)."""
    return "–" if x is None else f"{x / 1e3:.1f} kPa"


def mm(x) -> str:
    """A length, m, in mm ('–' for None)."""
    return "–" if x is None else f"{1e3 * x:.2f} mm"


def value(name: str, v: float) -> str:
    """A parameter's value: the yield pressure in kPa, any other in SI to four figures."""
    if name.endswith("yield_pressure") or name == "Y":
        return f"{v / 1e3:.3f} kPa"
    return f"{v:.4g}"


def origin_lines(origin: dict) -> list[str]:
    """Where the fixed parameters came from: recorded beside the data, fixed by ``--param``."""
    lines = []
    if origin.get("recorded_beside_data"):
        shown = ", ".join(f"{k} = {value(k, v)}" for k, v in origin["recorded_beside_data"].items())
        lines.append(f"  parameters recorded beside the data: {shown} (--param overrides)")
    if origin.get("fixed"):
        lines.append("  fixed by --param: " + ", ".join(f"{k} = {value(k, v)}" for k, v in origin["fixed"].items()))
    return lines


def data_name(summary: dict) -> str:
    """The name of the summary's data: the file's (or each file's, comma-separated), '' for none."""
    data = summary.get("data")
    if isinstance(data, list):
        return ", ".join(Path(d).name for d in data)
    return Path(data).name if data else ""
