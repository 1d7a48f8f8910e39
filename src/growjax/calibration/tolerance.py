"""Rig tolerances: the uncertainty of the parameters a fit or posterior holds fixed.

Every fixed parameter of the rig is known only to a tolerance (a datasheet value, a measurement, a tuning
that drifts). A tolerance here is the parameter's **relative standard uncertainty** u (one standard
deviation of ln ψ): the parameter's true value is taken as ψ·exp(b), b ~ N(0, u²). The likelihood carries it
(:mod:`growjax.calibration.discrepancy`): the length's sensitivity to each toleranced parameter, g(t) = ∂L/∂ln ψ, enters
as a random term g(t)·b whose variance the data cannot shrink below what they say of b. The uncertainty
budget then reports how much of each fitted parameter's interval each tolerance accounts for.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from growjax.model import params as gp

# Relative standard uncertainties (1 sd of ln ψ) of the reference rig, with the reason for each.
# Parameters whose tolerance moves the length by far less than the noise (hose length and wall compliance,
# the saline's viscosity) are left out of the default: each tolerance costs one simulation per fit.
DEFAULT_BUDGET = {
    # The controller's gains are software values, but the model's ideal torque source stands for a real motor
    # driver whose effective loop gain differs from the programmed one.
    "pid.proportional": 0.05,
    "pid.integral": 0.05,
    # Viscous friction of the lead screw: a lumped estimate, not measured on the rig.
    "pump.screw_viscous_friction": 0.2,
    # Syringe bore: a catalogue value, ±1 % in diameter.
    "pump.syringe_area": 0.02,
    # Tank volume (its length at fixed section): measured by rule.
    "tank.length": 0.05,
    # Friction of the catheter inside the robot: estimated.
    "robot.catheter_friction": 0.2,
}


def default_budget(base: gp.Parameters) -> dict[str, float]:
    """The default tolerances {qualified name: relative sd} for the parameters ``base`` has."""
    names = set(gp.parameter_names(base))
    return {n: u for n, u in DEFAULT_BUDGET.items() if n in names}


def parse(text: str) -> tuple[str, float]:
    """``NAME=REL`` (a relative standard uncertainty, e.g. ``Kp=0.1``) → (name, REL); ValueError naming the problem."""
    if "=" not in text:
        raise ValueError(f"--tolerance expects NAME=REL (a relative standard uncertainty), got {text!r}")
    name, value = (s.strip() for s in text.split("=", 1))
    try:
        rel = float(value)
    except ValueError:
        raise ValueError(f"--tolerance {name}: {value!r} is not a number") from None
    if not 0.0 <= rel < 1.0:
        raise ValueError(f"--tolerance {name}={rel}: a relative uncertainty must lie in [0, 1) (0.1 is 10 %)")
    return name, rel


def budget(base: gp.Parameters, overrides: dict | None = None, free=(), use_default: bool = True) -> dict[str, float]:
    """The tolerances in force: the default budget (``use_default``) with ``overrides`` {name: rel} on top, names
    resolved (aliases such as ``Kp`` allowed), zero entries and the fitted parameters ``free`` dropped.

    A toleranced parameter must be positive (it is perturbed in ln ψ); ValueError names one that is not.
    """
    out = default_budget(base) if use_default else {}
    for name, rel in (overrides or {}).items():
        out[gp.resolve_name(base, name)] = float(rel)
    free = {gp.resolve_name(base, n) for n in free}
    out = {n: u for n, u in out.items() if u > 0.0 and n not in free}
    for n in out:
        if not float(gp.get(base, n)) > 0.0:
            raise ValueError(f"parameter {n} = {gp.get(base, n)} cannot carry a relative tolerance: it is not positive")
    return out


def rig_draws(n: int, base: gp.Parameters, tolerances: dict, seed: int = 0) -> dict:
    """Draws of the rig within its tolerances as {qualified name: (n,) array}: each toleranced parameter ψ·exp(u z),
    z ~ N(0, 1) independent (seeded), u its relative standard uncertainty in ``tolerances`` {name: u} (aliases
    allowed, zeros dropped). {} for no tolerances."""
    tol = budget(base, tolerances, use_default=False)
    rng = np.random.default_rng([seed, 1])  # a stream apart from a posterior's draws
    return {k: float(gp.get(base, k)) * np.exp(u * rng.standard_normal(n)) for k, u in tol.items()}


def sensitivity(length_of, base: gp.Parameters, tol: dict, reference=None, central: bool = False) -> np.ndarray:
    """g (n, q): the length's change, m, per unit ln ψ of each toleranced parameter of ``tol`` {name: u}: the secant
    from ψ to ψ·e^u (the effect of an error the size of the tolerance), or with ``central`` from ψ·e^(−u/2) to
    ψ·e^(u/2) (the slope at ψ, where a fit linearises again at the rig it found). ``length_of(rig) → (n,)`` m is
    the model's length for a rig (the caller's own compiled run); ``reference`` (n,) m its value at ``base`` if
    already known. RuntimeError where a run failed."""
    l0 = None if central else np.asarray(length_of(base) if reference is None else reference, float)

    def at(n, f):
        return np.asarray(length_of(gp.replace(base, **{n: gp.get(base, n) * np.exp(f)})), float)

    def column(item):
        n, u = item
        return (at(n, 0.5 * u) - at(n, -0.5 * u)) / u if central else (at(n, u) - l0) / u

    # the runs are independent: one thread per core (a compiled run releases the GIL; the result is the same)
    with ThreadPoolExecutor(max_workers=max(1, min(len(tol), os.cpu_count() or 1))) as pool:
        cols = list(pool.map(column, tol.items()))
    g = np.stack(cols, axis=1)
    if not np.all(np.isfinite(g)):
        raise RuntimeError("the model failed while measuring the rig's tolerance sensitivities")
    return g


def rig_at(base: gp.Parameters, names, centre) -> gp.Parameters:
    """``base`` with the toleranced parameters ``names`` (q,) at ψ₀·e^centre (``centre`` (q,) relative errors
    ln(ψ/ψ₀) in their order; None: ``base`` unchanged)."""
    if centre is None:
        return base
    return gp.replace(base, **{name: gp.get(base, name) * np.exp(centre[j]) for j, name in enumerate(names)})


def length_sensitivity(
    theta: dict, base: gp.Parameters, inputs, config, times, tol: dict, central: bool = False
) -> np.ndarray:
    """g (n, q): the model's length change (m) at ``times`` (n,) s per unit ln ψ of each toleranced parameter of
    ``tol``, the secant from ψ to ψ·e^u (``central``: the slope at ψ, :func:`sensitivity`) at the values
    ``theta`` {qualified name: value} (one compiled run of the model, the rig and θ as its arguments: compiled
    once per configuration and shapes)."""
    from growjax.simulation.simulate import as_arrays, input_breaks, sample_times

    ts = sample_times(jnp.asarray(times, float), config)
    values = {n: jnp.asarray(v, float) for n, v in theta.items()}
    breaks = input_breaks(inputs, config)
    return sensitivity(
        lambda rig: _length(rig, values, inputs, breaks, config, ts), as_arrays(base), tol, central=central
    )


@eqx.filter_jit
def _length(rig, theta, inputs, breaks, config, ts):
    """The model's length (m) at ``ts`` for the rig ``rig`` with ``theta`` set; NaN where the run failed."""
    from growjax.simulation.simulate import simulate
    from growjax.simulation.trajectory import OK

    traj = simulate(gp.replace(rig, **theta), inputs, config, ts=ts, breaks=breaks)
    return jnp.where(traj.status == OK, traj.length, jnp.nan)
