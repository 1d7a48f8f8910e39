"""The box a sweep covers (`Dimension`: one parameter's range) and its Latin-hypercube design.

`Dimension`, `paper_box` and `latin_hypercube` live with the parameters (`growjax.model.params`), where the fit's
scout also draws its points; the sweep adds the command line's form of a range.
"""

from __future__ import annotations

from growjax.model import params as gp
from growjax.model.params import Dimension, latin_hypercube, paper_box

__all__ = ["Dimension", "latin_hypercube", "paper_box", "parse_dimension"]


def parse_dimension(text: str, params: gp.Parameters) -> Dimension:
    """A `Dimension` from its command-line form.

    Args:
        text: ``NAME=LOW:HIGH`` or ``NAME=LOW:HIGH:log``; NAME as `growjax.replace` accepts it.
        params: the parameters that resolve NAME to its qualified name.

    Returns:
        The dimension.

    Raises:
        ValueError: naming ``--range``, the text and what is wrong with it (its form, its bounds or its name).
    """
    if "=" not in text:
        raise ValueError(f"--range expects NAME=LOW:HIGH[:log], got {text!r}")
    name, rng = text.split("=", 1)
    parts = rng.split(":")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] not in ("log", "lin")):
        raise ValueError(f"--range {name}: range must be LOW:HIGH or LOW:HIGH:log, got {rng!r}")
    try:
        low, high = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"--range {name}: bounds {rng!r} are not numbers") from None
    try:
        return Dimension(gp.resolve_name(params, name.strip()), low, high, len(parts) == 3 and parts[2] == "log")
    except ValueError as err:
        raise ValueError(f"--range {text}: {err}") from None
