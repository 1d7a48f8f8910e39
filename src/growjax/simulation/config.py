"""How to simulate: the configuration (fidelity), drive, window, tolerances and switch widths."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from growjax.model.params import DRIVES

__all__ = ["FIDELITIES", "TANGENTS", "Config"]

FIDELITIES = ("fast", "reference")
TANGENTS = ("auto", "forward", "differences")

# Default tolerances (on states scaled to O(1)) per fidelity.
_DEFAULT_RTOL = {"fast": 1e-4, "reference": 1e-6}
_DEFAULT_MAX_STEPS = {"fast": 8_000, "reference": 200_000}
_DEFAULT_FIRST_STEP = 1e-5  # s


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config:
    """Static settings of a simulation (hashable: a static argument of ``jit``).

    Attributes:
        fidelity: ``"fast"`` (lumped lines, massless platform, Rosenbrock solver: `growjax.simulation.fast`)
            or ``"reference"`` (the shipped network node by node, Kvaerno5: `growjax.simulation.reference`).
        drive: ``"forward"`` (pressure demand, PID, ideal torque) or ``"inverse"`` (desired length, stepper).
        t0, t1: integration window, s (the shipped model starts at 0.001 s).
        save_dt: spacing of the default save grid, s.
        rtol, atol: step-size control on the scaled states (None: 1e-4 fast, 1e-6 reference).
        max_steps: solver step budget (None: 8 000 fast, 200 000 reference).
        first_step: (fast only) size of the solver's first attempted step, s (None: 10 µs). A model stepped
            sample by sample (a plant, a filter) sets it near its sample interval: each window then opens at
            that size instead of growing to it from 10 µs (a 10 ms window of the published pulse: about 6
            steps → 2); the step-size control shrinks it where the window needs less.
        stop_at_pressure_limit: stop the run (status 1) when the sensed pressure crosses the membrane
            limit; otherwise the crossing is only flagged (``limit_time``) and the run goes on.
        velocity_eps: regularisation of |v|^n at v = 0, m/s.
        stop_width: C¹ band of end stops, m (and m/s for their velocity gate).
        crack_width: C¹ band of the check-valve opening, Pa.
        switch_width: band over which the bypass opens as the valve pressure drop turns negative, Pa.
        flow_width: band of the nozzle's loss-coefficient switch, m³/s.
        adjoint: how derivatives are taken. ``"reverse"``: ``jax.grad`` and forward mode both work (reference:
            diffrax's checkpointed adjoint; fast: the forward-mode Jacobian in the leaves that carry tangents,
            contracted with them). ``"forward"``: forward mode only (``jax.jvp``/``jacfwd``), the cheapest for
            a few directions (reference: diffrax's forward mode; fast: sensitivities along the tangents).
        tangents: (fast only) how the forward sensitivities take the field's derivative:
            ``"forward"`` (``jax.jvp``), ``"differences"`` (central differences) or ``"auto"`` (forward mode
            where the solver's loop is compiled whole, ``small_loops``, or under the Lockhart law;
            differences otherwise). Both agree to ~1e-5 relative; only the speed differs.
        small_loops: (fast only) the integrator writes its linear solve in elementwise operations so that
            XLA:CPU can compile its loop into one kernel (`growjax.simulation.xla_flags`); the rounding differs from
            LAPACK's. None: whether ``XLA_FLAGS`` sets the small-loop limit, read by `resolved` where a
            simulation starts (outside any trace), so the compiled program is keyed on the value in force.
        quick_compile: whether programs are compiled with XLA:CPU's older emitters
            (`growjax.simulation.xla_flags.QUICK_COMPILE`): quicker compiles, slower runs, other rounding (a 10 s run
            moves by up to 0.3 µm). A program under ``jax.jit`` takes the process's setting (``XLA_FLAGS``, fixed
            when JAX starts: `growjax.simulation.xla_flags.apply_quick_compile`); a sweep compiles its own and takes
            either. None: the setting in force (a sweep: quick up to ``growjax.sweep.QUICK_COMPILE_ROWS`` sets),
            read by `resolved`; a value the program cannot take raises ``ValueError`` there.

    A field that does not apply to the chosen fidelity must keep its default (``ValueError`` otherwise).
    """

    fidelity: str = "fast"
    drive: str = "forward"
    t0: float = 0.001
    t1: float = 10.0
    save_dt: float = 0.01
    rtol: float | None = None
    atol: float | None = None
    max_steps: int | None = None
    first_step: float | None = None
    stop_at_pressure_limit: bool = True
    velocity_eps: float = 1e-6
    stop_width: float = 1e-6
    crack_width: float = 50.0
    switch_width: float = 10.0
    flow_width: float = 1e-10
    adjoint: str = "reverse"
    tangents: str = "auto"
    small_loops: bool | None = None
    quick_compile: bool | None = None

    def __post_init__(self):
        if self.fidelity not in FIDELITIES:
            raise ValueError(f"fidelity must be one of {FIDELITIES}, got {self.fidelity!r}")
        if self.drive not in DRIVES:
            raise ValueError(f"drive must be one of {DRIVES}, got {self.drive!r}")
        if not (math.isfinite(self.t0) and math.isfinite(self.t1)) or not self.t1 > self.t0:
            raise ValueError(f"t1 ({self.t1} s) must be after t0 ({self.t0} s)")
        if not self.save_dt > 0:
            raise ValueError(f"save_dt must be positive, got {self.save_dt} s")
        if self.adjoint not in ("reverse", "forward"):
            raise ValueError(f"adjoint must be 'reverse' or 'forward', got {self.adjoint!r}")
        if self.tangents not in TANGENTS:
            raise ValueError(f"tangents must be one of {TANGENTS}, got {self.tangents!r}")
        for name in _FIDELITY_FIELDS[_other(self.fidelity)]:
            default = _DEFAULTS[name]
            if getattr(self, name) != default:
                raise ValueError(
                    f"{name} applies to the {_other(self.fidelity)!r} fidelity only; with fidelity="
                    f"{self.fidelity!r} leave it at its default {default!r}"
                )
        if self.first_step is not None and not (math.isfinite(self.first_step) and self.first_step > 0):
            raise ValueError(f"first_step must be a positive time (s), got {self.first_step}")
        for name in ("rtol", "atol"):
            v = getattr(self, name)
            if v is not None and not 0 < v < 1:
                raise ValueError(f"{name} must be in (0, 1), got {v}")

    @property
    def tolerances(self) -> tuple[float, float]:
        """(rtol, atol) in use."""
        rtol = self.rtol if self.rtol is not None else _DEFAULT_RTOL[self.fidelity]
        return rtol, self.atol if self.atol is not None else rtol

    @property
    def initial_step(self) -> float:
        """Size of the fast solver's first attempted step, s."""
        return self.first_step if self.first_step is not None else _DEFAULT_FIRST_STEP

    @property
    def step_budget(self) -> int:
        return self.max_steps if self.max_steps is not None else _DEFAULT_MAX_STEPS[self.fidelity]

    def save_grid(self) -> np.ndarray:
        """Default output times, s: every ``save_dt`` from t0, and t1."""
        n = max(1, math.ceil((self.t1 - self.t0) / self.save_dt - 1e-9))
        return np.append(self.t0 + self.save_dt * np.arange(n), self.t1)

    def resolved(self) -> Config:
        """This configuration with every option left to the environment made explicit (``small_loops`` and
        ``quick_compile`` from ``XLA_FLAGS``): what a compiled program is keyed on. Call it outside any trace."""
        from growjax.simulation import xla_flags

        quick = xla_flags.quick_compile_in_force()
        if self.quick_compile is not None and self.quick_compile != quick:
            raise ValueError(
                f"quick_compile={self.quick_compile}, but this program compiles with quick_compile={quick}: "
                "the emitters are the process's (XLA_FLAGS before JAX starts, "
                "growjax.simulation.xla_flags.apply_quick_compile); leave quick_compile None"
            )
        small_loops = xla_flags.applied() if self.fidelity == "fast" and self.small_loops is None else self.small_loops
        if (small_loops, quick) == (self.small_loops, self.quick_compile):
            return self
        return dataclasses.replace(self, small_loops=small_loops, quick_compile=quick)

    def replace(self, **changes: Any) -> Config:
        """A copy with the given fields (``changes``: {field: value}) changed; validated as a new `Config`."""
        return dataclasses.replace(self, **changes)


# Fields that apply to one fidelity only: with the other they must keep their defaults.
_FIDELITY_FIELDS = {"fast": ("tangents", "small_loops", "first_step"), "reference": ("flow_width",)}
_DEFAULTS = {f.name: f.default for f in dataclasses.fields(Config)}


def _other(fidelity: str) -> str:
    return "reference" if fidelity == "fast" else "fast"
