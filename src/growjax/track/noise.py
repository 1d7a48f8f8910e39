"""The uncertainty the filter starts from and the noise it adds, from what calibration found.

Three kinds of state join the model's own:

* **Parameters** (`StateParameter`): a rig parameter held at its nominal value is known only to its
  tolerance (`growjax.calibration.tolerance`): a static state b = ln(ψ/ψ₀) with prior N(0, u²) and no noise.
  A parameter that may vary slowly (Y, a leak coefficient) is a random walk, its coordinate's increments
  N(0, q² Δt); q is a forgetting rate (too small and the band collapses on a drifting value, too large and the
  estimate wanders).
* **Inputs** (`InputState`): an unrecorded input (the pressure demand, the stepper's step count, the
  catheter's insertion) held over each sample interval at a level that is a random walk.
* **The model's discrepancy** (`Discrepancy`): the length error δ(t) a fit found, a Matérn-3/2 process
  of amplitude a and time scale ℓ, is a two-state linear SDE (δ, δ') whose transition over Δt is exact
  (`growjax.calibration.discrepancy.matern_transition`); the length the sensors and the band see is the
  model's plus δ.

Every state is carried in a coordinate of order one: a parameter as ln(ψ/ψ₀), or as (ψ − ψ₀) in units of its prior
sd where ψ₀ is 0 (an effect switched off); inputs and the discrepancy divided by a fixed scale.
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from growjax.calibration import discrepancy as dc
from growjax.calibration import tolerance as tl
from growjax.model import params as gp

DEFAULT_PRIOR_SD = 0.1  # relative sd of an estimated parameter with no calibrated uncertainty (ln ψ)
DEFAULT_WALK = 0.01  # 1/√s: a 1 % random walk per √s (8 % over 60 s)
DISCREPANCY_SCALE = 1e-3  # m: δ carried in mm (δ' in mm/s)

# Inputs that may be estimated: their field of ``growjax.Inputs``, the column that reports them, the scale the state
# carries them in (SI per unit), the drive they belong to (None: both), and their default prior sd and walk.
INPUTS = {
    "pressure_demand": ("pressure_demand_Pa", 1e5, "forward", 1e5, 3e5),
    "steps": ("steps", 10.0, "inverse", 10.0, 30.0),
    "catheter_length": ("catheter_length_m", 1e-2, None, 1e-3, 1e-2),
}


@dataclasses.dataclass(frozen=True)
class StateParameter:
    """A model parameter carried in the state.

    Attributes:
        name: its qualified name (``robot.yield_pressure``).
        prior_sd: sd of ψ at the start: relative for ``log``, else in its unit.
        walk: sd of ψ's random-walk increments per √s, as ``prior_sd`` (0: static).
        log: the coordinate is ln(ψ/ψ₀) (ψ positive) rather than (ψ − ψ₀)/prior_sd.
        tolerance: a rig parameter known to its tolerance (reported in the summary), not one asked for.
    """

    name: str
    prior_sd: float
    walk: float = 0.0
    log: bool = True
    tolerance: bool = False

    def __post_init__(self):
        if not (math.isfinite(self.prior_sd) and self.prior_sd >= 0):
            raise ValueError(f"the prior sd of {self.name} must be a non-negative number, got {self.prior_sd}")
        if not (math.isfinite(self.walk) and self.walk >= 0):
            raise ValueError(f"the random walk of {self.name} must be a non-negative number, got {self.walk}")

    @property
    def scale(self) -> float:
        """Units of ψ per unit of a linear coordinate (its prior sd, so that the coordinate is of order one); 1 for
        a log coordinate."""
        return 1.0 if self.log or self.prior_sd == 0 else self.prior_sd

    def value(self, nominal, coordinate):
        """ψ (its unit) at ``coordinate`` about ``nominal`` ψ₀: ψ₀·e^c, or ψ₀ + c·scale."""
        return nominal * jnp.exp(coordinate) if self.log else nominal + coordinate * self.scale


@dataclasses.dataclass(frozen=True)
class InputState:
    """An unrecorded input carried in the state: its level, held over each sample interval, is a random walk.

    Attributes:
        field: the field of ``growjax.Inputs`` it replaces: ``"pressure_demand"`` (Pa), ``"steps"`` or
            ``"catheter_length"`` (m).
        prior_mean: its level at the start, SI.
        prior_sd: sd of that level, SI.
        walk: sd of its increments per √s, SI.
    """

    field: str
    prior_mean: float = 0.0
    prior_sd: float | None = None
    walk: float | None = None

    def __post_init__(self):
        if self.field not in INPUTS:
            raise ValueError(f"an estimated input is one of {sorted(INPUTS)}, got {self.field!r}")
        column, scale, drive, sd, walk = INPUTS[self.field]
        object.__setattr__(self, "prior_sd", sd if self.prior_sd is None else float(self.prior_sd))
        object.__setattr__(self, "walk", walk if self.walk is None else float(self.walk))
        for what in ("prior_sd", "walk"):
            v = getattr(self, what)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"the {what} of the estimated {self.field} must be a non-negative number, got {v}")

    @property
    def column(self) -> str:
        return INPUTS[self.field][0]

    @property
    def scale(self) -> float:
        """SI units per unit of its state."""
        return INPUTS[self.field][1]

    @property
    def drive(self) -> str | None:
        return INPUTS[self.field][2]


@dataclasses.dataclass(frozen=True)
class Discrepancy:
    """The model's length error as a Matérn-3/2 process: ``amplitude`` a (m), ``time_scale`` ℓ (s)."""

    amplitude: float
    time_scale: float

    def __post_init__(self):
        if not (math.isfinite(self.amplitude) and self.amplitude > 0):
            raise ValueError(f"the discrepancy's amplitude must be positive (m), got {self.amplitude}")
        if not (math.isfinite(self.time_scale) and self.time_scale > 0):
            raise ValueError(f"the discrepancy's time scale must be positive (s), got {self.time_scale}")

    @classmethod
    def of(cls, hyper: dc.Hyper) -> Discrepancy | None:
        """From a fit's residual model (None where it found no discrepancy)."""
        a = float(hyper.amplitude)
        return cls(a, float(hyper.time_scale)) if a > 0 else None

    def transition(self, dt):
        """(A (2, 2), Q (2, 2)) of (δ, δ') in the state's scale over ``dt`` s."""
        a, q, _ = dc.matern_transition(dt, self.amplitude / DISCREPANCY_SCALE, self.time_scale)
        return a, q

    def stationary(self):
        """Stationary covariance (2, 2) of (δ, δ') in the state's scale."""
        return dc.matern_transition(0.0, self.amplitude / DISCREPANCY_SCALE, self.time_scale)[2]


def rig_parameters(base: gp.Parameters, tolerances: dict | None = None, *, default: bool = True, free=()) -> tuple:
    """The rig's toleranced parameters as static states: ln(ψ/ψ₀) ~ N(0, u²) for each of
    `growjax.calibration.tolerance.budget` (the default budget where ``default``, ``tolerances`` {name: u} on
    top; the parameters ``free`` left out, as the estimated ones are)."""
    budget = tl.budget(base, tolerances, free=free, use_default=default)
    return tuple(StateParameter(name, float(u), tolerance=True) for name, u in budget.items())


def estimated_parameter(
    base: gp.Parameters, name: str, *, prior_sd: float | None = None, walk: float | None = None
) -> StateParameter:
    """A parameter to estimate: ln ψ (or ψ itself where its nominal value is 0: an effect switched off) with
    prior sd ``prior_sd`` (default 10 %; in its unit for a linear coordinate: required there) and random walk
    ``walk`` per √s (default 1 %/√s; in its unit for a linear coordinate, default 0).

    Raises:
        ValueError: an unknown parameter, or one at 0 with no prior sd.
    """
    qualified = gp.resolve_name(base, name)
    nominal = float(gp.get(base, qualified))
    log = nominal > 0
    if not log and prior_sd is None:
        raise ValueError(f"{qualified} is 0 (off) here: give its prior sd in its unit to estimate it")
    return StateParameter(
        qualified,
        DEFAULT_PRIOR_SD if prior_sd is None else float(prior_sd),
        (DEFAULT_WALK if log else 0.0) if walk is None else float(walk),
        log,
    )


def parameter_noise(parameters: tuple, dt) -> jnp.ndarray:
    """Variances (k,) of the parameters' coordinates' increments over ``dt`` s."""
    walks = np.array([p.walk / p.scale for p in parameters], float)
    return jnp.asarray(walks**2) * dt


def parameter_prior(parameters: tuple) -> np.ndarray:
    """Variances (k,) of the parameters' coordinates at the start."""
    return np.array([(p.prior_sd / p.scale) ** 2 for p in parameters], float)


def input_noise(inputs: tuple, dt) -> jnp.ndarray:
    """Variances (j,) of the estimated inputs' states' increments over ``dt`` s."""
    walks = np.array([i.walk / i.scale for i in inputs], float)
    return jnp.asarray(walks**2) * dt


__all__ = [
    "DEFAULT_PRIOR_SD",
    "DEFAULT_WALK",
    "DISCREPANCY_SCALE",
    "INPUTS",
    "Discrepancy",
    "InputState",
    "StateParameter",
    "estimated_parameter",
    "input_noise",
    "parameter_noise",
    "parameter_prior",
    "rig_parameters",
]
