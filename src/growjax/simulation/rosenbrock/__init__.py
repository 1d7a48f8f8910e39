"""An adaptive Rosenbrock integrator for the fast configuration, with dense output and a stop event.

A Rosenbrock method replaces the Newton iterations of an implicit Runge–Kutta method by one
linear solve per stage with W = I − hγJ, J = ∂f/∂y (Hairer & Wanner, IV.7)::

    W k_i = h f(t0 + α_i h, y0 + Σ_j α_ij k_j) + h J Σ_j γ_ij k_j + γ_i h² ∂f/∂t
    y1 = y0 + Σ b_i k_i,   error estimate Σ (b_i − b̂_i) k_i.

ROS34PW2 (Rang & Angermann 2005) is L-stable and stiffly accurate, so the stiff modes of the
hydraulics (opened bypass, ~1e5 s⁻¹; stepper rotor, ~3e5 s⁻¹) are damped at steps set by the
slow dynamics; it keeps every linear invariant of the field (the volume balance) to rounding.

Why not ``diffrax.diffeqsolve``: diffrax ships no Rosenbrock method, and a forward-mode
derivative through its loop is not under any step control. Here J is the exact Jacobian at the
step's start, held constant under differentiation (a W-method: order 3 for any matrix in place
of J, so the tangents are the same method applied to the sensitivity equations). A tangent step
is stable only while J stays close to the true Jacobian over the step, which fails where a stiff
mode switches on inside a step (the bypass opening). So every step also compares J at its end
with J at its start and is rejected unless ``h γ ‖J₁ − J₀‖∞ ≤ 1``: the step sequence depends only
on the primal solution, and the tangents it carries are stable and consistent. The end's J is the
next step's start's, so the check costs nothing extra.

In a batch (``batched``: a sweep) four choices differ, each faster there (``benchmarks/sweep.py``): the
Jacobian and ∂f/∂t are taken in forward mode (the primal once, then one tangent per state and for time)
instead of by forward differences; the stages are a loop (one copy of the field in the compiled program: a
shorter compile); f, ∂f/∂t and J at t0 come from an opening attempt of zero length, the loop's first, instead
of a second copy of that code before the loop; and W⁻¹ and the variation check are written with the batch axis
last, in elementwise operations (``custom_vmap`` rules). A run may also interpolate its save times inside the
loop (``save_ts``, used by batches) instead of recording every step: a sweep member then carries (T, n) values,
not (max_steps, n) step records.

Other choices: steps land on every declared input break (a jump is approached from the left and
left from the right, one ulp either side; a slope break is landed on); the accepted steps are
recorded, and the solution on the save grid is their cubic Hermite interpolant, evaluated after
the loop; a stop event (the pressure limit) is located by bisection on that interpolant.
Derivatives: forward mode (``jax.jvp``, ``jax.jacfwd``) through the loop; reverse mode is not
supported (the loop's length is not static).

Layout: ``_method`` (the tableau as data, one step's stage solves), ``_slopes`` (F, ∂F/∂t and J at a point),
``_linear`` (W⁻¹ and the variation check, one run or a batch), ``_step_control`` (landing on breaks, error
norm, step size), ``_saving`` (step records, interpolant, save times), ``_events`` (the stop event's location)
and ``_integrator`` (`integrate`, the loop that composes them).
"""

from growjax.simulation.rosenbrock._integrator import EVENT, FAILED, OK, Result, integrate
from growjax.simulation.rosenbrock._linear import batchable_inverse, batchable_variation, inverse, spread, variation
from growjax.simulation.rosenbrock._method import ROS34PW2, RosenbrockTableau
from growjax.simulation.rosenbrock._saving import SAVE_WINDOW, Steps, evaluate, hermite

__all__ = [
    "EVENT",
    "FAILED",
    "OK",
    "ROS34PW2",
    "SAVE_WINDOW",
    "Result",
    "RosenbrockTableau",
    "Steps",
    "batchable_inverse",
    "batchable_variation",
    "evaluate",
    "hermite",
    "integrate",
    "inverse",
    "spread",
    "variation",
]
