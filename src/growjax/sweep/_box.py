"""The box a sweep covers (`Dimension`: one parameter's range) and its Latin-hypercube design."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from jaxtyping import ArrayLike, Float

from growjax.model import params as gp

__all__ = ["Dimension", "latin_hypercube", "paper_box", "parse_dimension"]


@dataclasses.dataclass(frozen=True)
class Dimension:
    """One swept parameter and its range.

    Attributes:
        name: qualified parameter name, ``block.field`` (e.g. ``"robot.yield_pressure"``).
        low: lower bound, SI units of the parameter.
        high: upper bound, SI units; greater than ``low``.
        log: a log scale (then ``low > 0``) instead of a linear one.

    Raises:
        ValueError: for bounds that are not finite, not ordered, or not positive on a log scale.
    """

    name: str
    low: float
    high: float
    log: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or not self.high > self.low:
            raise ValueError(f"{self.name}: need finite LOW < HIGH, got {self.low}:{self.high}")
        if self.log and self.low <= 0:
            raise ValueError(f"{self.name}: a log scale needs LOW > 0, got {self.low}")

    def from_unit(self, u: Float[ArrayLike, "*shape"]) -> Float[np.ndarray, "*shape"]:
        """The parameter value at each point of the unit interval.

        Args:
            u: points in [0, 1].

        Returns:
            The values, SI units, of ``u``'s shape: linear or logarithmic between ``low`` and ``high``.
        """
        u = np.asarray(u, float)
        if self.log:
            return np.exp(np.log(self.low) + u * (np.log(self.high) - np.log(self.low)))
        return self.low + u * (self.high - self.low)


def paper_box() -> tuple[Dimension, ...]:
    """The published investigation's box.

    Returns:
        The growth exponent n 0.9–1.1, the yield pressure Y 5–15 kPa and the extensibility 4000–10000.
    """
    return (
        Dimension("robot.growth_exponent", 0.9, 1.1),
        Dimension("robot.yield_pressure", 5e3, 15e3),
        Dimension("robot.extensibility", 4000.0, 10000.0),
    )


def parse_dimension(text: str, params: gp.Parameters) -> Dimension:
    """A `Dimension` from its command-line form.

    Args:
        text: ``NAME=LOW:HIGH`` or ``NAME=LOW:HIGH:log``; NAME as `growjax.replace` accepts it.
        params: the parameters that resolve NAME to its qualified name.

    Returns:
        The dimension.

    Raises:
        ValueError: naming what is wrong with ``text`` (its form, its bounds or its name).
    """
    if "=" not in text:
        raise ValueError(f"--param expects NAME=LOW:HIGH[:log], got {text!r}")
    name, rng = text.split("=", 1)
    parts = rng.split(":")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] not in ("log", "lin")):
        raise ValueError(f"--param {name}: range must be LOW:HIGH or LOW:HIGH:log, got {rng!r}")
    try:
        low, high = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"--param {name}: bounds {rng!r} are not numbers") from None
    return Dimension(gp.resolve_name(params, name.strip()), low, high, len(parts) == 3 and parts[2] == "log")


def latin_hypercube(dims: Sequence[Dimension], n: int, seed: int) -> Float[np.ndarray, "n d"]:
    """A Latin-hypercube design of the box (``scipy.stats.qmc.LatinHypercube``, seeded).

    Args:
        dims: the box, d dimensions.
        n: the number of points, at least 1.
        seed: the random generator's seed.

    Returns:
        The (n, d) design in parameter units, SI: one point in each of n strata of every dimension.

    Raises:
        ValueError: for ``n < 1``.
    """
    from scipy.stats import qmc

    if n < 1:
        raise ValueError(f"a sweep needs n ≥ 1 points, got {n}")
    unit = qmc.LatinHypercube(d=len(dims), seed=np.random.default_rng(seed)).random(n)
    return np.column_stack([d.from_unit(unit[:, i]) for i, d in enumerate(dims)])
