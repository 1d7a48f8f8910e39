"""The null distribution of a nested likelihood-ratio test whose added parameters start on their boundary.

An effect absent from the model has its parameter at 0, the edge of its range, so the statistic 2ΔlogL of adding
it is not χ²₁ under the null: each copy of the parameter (one per robot of a set) is 0 half the time, and
2ΔlogL is distributed as the mixture Σⱼ C(c, j) 2⁻ᶜ χ²ⱼ over its c copies (χ²₀ a point mass at 0). Discovery
tests the catalogue's effects by this rule, and the discrimination design reads its threshold.
"""

from __future__ import annotations

from scipy import optimize, special, stats

__all__ = ["boundary_p_value", "boundary_threshold"]


def boundary_threshold(rate: float, copies: int = 1) -> float:
    """The 2ΔlogL a nested test clears with probability ``rate`` under the null.

    Args:
        rate: the false-positive rate, in (0, 0.5).
        copies: the copies of the effect's parameter (one per robot), each on its boundary 0 under the null.

    Returns:
        The threshold: for one copy (½χ²₀ + ½χ²₁, the single experiment's rule) χ²₁'s upper 2·``rate`` point.
    """
    if copies == 1:
        return float(stats.chi2.isf(2.0 * rate, df=1))
    return float(optimize.brentq(lambda c: boundary_p_value(c, copies) - rate, 1e-9, 1e3))


def boundary_p_value(lr: float, copies: int = 1) -> float:
    """P(2ΔlogL > ``lr``) under the null of `boundary_threshold` (1 for ``lr`` ≤ 0).

    Args:
        lr: the statistic 2ΔlogL.
        copies: the copies of the effect's parameter, each on its boundary 0 under the null.

    Returns:
        The probability Σⱼ₌₁ᶜ C(c, j) 2⁻ᶜ P(χ²ⱼ > ``lr``).
    """
    if lr <= 0:
        return 1.0
    return float(sum(special.comb(copies, j) * 0.5**copies * stats.chi2.sf(lr, df=j) for j in range(1, copies + 1)))
