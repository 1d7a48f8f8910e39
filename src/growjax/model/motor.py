"""Drives of the syringe pump.

* forward drive: PID on the sensed pressure → two ideal torque sources (paper eq. 1);
* inverse drive: desired length → syringe displacement (eq. 2) → step counter →
  stepper driver → permanent-magnet stepper motor.

The step controller is open loop in the demand, so its whole step sequence is
computed once from the input (`step_schedule`) and enters the ODE as data.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "PID",
    "StepperMotor",
    "ideal_torque_drive_force",
    "motor_derivatives",
    "motor_equilibrium_offset",
    "paper_pid",
    "pid_output",
    "step_schedule",
    "winding_voltages",
]


class PID(eqx.Module):
    """Continuous parallel PID with filtered derivative: C(s) = P + I/s + D N s/(s + N).

    Shipped gains P 20, I 80, D 0.5, N 100 s⁻¹ (the paper quotes 80/25/0.5: `paper_pid`).
    Units: output Pa of equivalent syringe pressure per Pa of error.

    Attributes:
        proportional: K_P (–).
        integral: K_I, 1/s.
        derivative: K_D, s.
        filter_coefficient: N of the derivative filter, 1/s.
    """

    proportional: float = 20.0
    integral: float = 80.0
    derivative: float = 0.5
    filter_coefficient: float = 100.0


def paper_pid() -> PID:
    """The PID with the gains printed in the paper (K_P 80, K_I 25, K_D 0.5)."""
    return PID(80.0, 25.0, 0.5, 100.0)


def pid_output(
    pid: PID, error: Float[ArrayLike, "*b"], z_integral: Float[ArrayLike, "*b"], z_filter: Float[ArrayLike, "*b"]
) -> tuple[Float[Array, "*b"], Float[Array, "*b"], Float[Array, "*b"]]:
    """The controller's output and state derivatives.

    Args:
        pid: the controller.
        error: the pressure error, Pa.
        z_integral: z_I, the error's integral, Pa·s.
        z_filter: z_D, the derivative filter's state, Pa.

    Returns:
        (u, Pa of equivalent syringe pressure; ż_I, Pa; ż_D, Pa/s).
    """
    d_term = pid.filter_coefficient * (error - z_filter)
    u = pid.proportional * error + pid.integral * z_integral + pid.derivative * d_term
    return u, error, d_term


def ideal_torque_drive_force(
    syringe_area: Float[ArrayLike, "*b"], n_syringes: int, u: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """Force on the platform from the torque sources: torque L·A_s·u/(2π) per screw → A_s·u per nut.

    Args:
        syringe_area: A_s, m².
        n_syringes: the syringes (and screws).
        u: the controller's output, Pa.

    Returns:
        The force, N.
    """
    return n_syringes * syringe_area * u


class StepperMotor(eqx.Module):
    """Permanent-magnet stepper (Minebea 08PM-K139BSTDCN data) with its full-step driver.

    Attributes:
        winding_resistance: R, Ω.
        winding_inductance: L, H.
        torque_constant: K_m, N·m/A.
        detent_torque: T_d, N·m.
        rotor_inertia: J, kg·m².
        rotor_damping: B, N·m/(rad/s).
        step_angle: full step, rad.
        supply_voltage: driver output amplitude V_m, V.
        controller_rate: f, Hz, of the step controller (undefined in the shipped model; see README).
        microstepping: the driver (static): False the shipped full-step driver, True a sine–cosine
            microstepping driver that takes a continuous step command (`winding_voltages`).
    """

    winding_resistance: float = 6.5
    winding_inductance: float = 3.2e-3
    torque_constant: float = 51.63e-3
    detent_torque: float = 2.5e-3
    rotor_inertia: float = 2.9e-7
    rotor_damping: float = 2.65e-5
    step_angle: float = math.radians(1.8)
    supply_voltage: float = 12.0
    controller_rate: float = 3.0
    microstepping: bool = eqx.field(static=True, default=False)

    @property
    def teeth(self) -> Float[ArrayLike, ""]:
        """Rotor teeth N_r = (π/2)/step angle."""
        return 0.5 * jnp.pi / self.step_angle


def winding_voltages(
    motor: StepperMotor, step_count: Float[ArrayLike, "*b"]
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    """Driver phase voltages at a step command.

    Full-step driver (the shipped one), integer k: (+,−),(+,+),(−,+),(−,−) by k mod 4.
    Microstepping driver (``motor.microstepping``), continuous k: √2 V (cos φ, sin φ), φ = −π/4 + kπ/2,
    equal to the full-step driver at every integer k and smooth in between (a deviation from the
    shipped model, added for control design: it removes the 3.1 mm grid of full steps).

    Args:
        motor: the motor and its driver.
        step_count: k, the step command.

    Returns:
        (v_A, v_B), V.
    """
    if motor.microstepping:
        phi = -0.25 * jnp.pi + 0.5 * jnp.pi * step_count
        amp = jnp.sqrt(2.0) * motor.supply_voltage
        return amp * jnp.cos(phi), amp * jnp.sin(phi)
    k = jnp.mod(step_count, 4)
    v_a = jnp.where(k < 2, 1.0, -1.0)
    v_b = jnp.where((k == 1) | (k == 2), 1.0, -1.0)
    return motor.supply_voltage * v_a, motor.supply_voltage * v_b


def motor_equilibrium_offset(motor: StepperMotor) -> Float[ArrayLike, ""]:
    """Rotor angle (rad) at which step 0 of the driver is a stable equilibrium: −π/(4 N_r)."""
    return -0.25 * jnp.pi / motor.teeth


def motor_derivatives(
    motor: StepperMotor,
    theta: Float[ArrayLike, "*b"],
    omega: Float[ArrayLike, "*b"],
    i_a: Float[ArrayLike, "*b"],
    i_b: Float[ArrayLike, "*b"],
    v_a: Float[ArrayLike, "*b"],
    v_b: Float[ArrayLike, "*b"],
) -> tuple[Float[Array, "*b"], Float[Array, "*b"], Float[Array, "*b"]]:
    """Electrical torque and current rates of the PM stepper.

    Args:
        motor: the motor.
        theta: the rotor angle, rad.
        omega: the rotor speed, rad/s.
        i_a: phase A's current, A.
        i_b: phase B's current, A.
        v_a: phase A's voltage, V.
        v_b: phase B's voltage, V.

    Returns:
        (T_e, N·m; di_A/dt, A/s; di_B/dt, A/s).
    """
    nr = motor.teeth
    km = motor.torque_constant
    e_a = -km * omega * jnp.sin(nr * theta)
    e_b = km * omega * jnp.cos(nr * theta)
    di_a = (v_a - motor.winding_resistance * i_a - e_a) / motor.winding_inductance
    di_b = (v_b - motor.winding_resistance * i_b - e_b) / motor.winding_inductance
    torque = -km * i_a * jnp.sin(nr * theta) + km * i_b * jnp.cos(nr * theta)
    torque = torque - motor.detent_torque * jnp.sin(4.0 * nr * theta)
    return torque, di_a, di_b


def step_schedule(
    demand_steps: Float[ArrayLike, " N"], times: Float[ArrayLike, " N"], rate: float, t0: float, t1: float
) -> tuple[Float[np.ndarray, " K"], Float[np.ndarray, " K"]]:
    """Steps issued by the shipped position controller for a demand in steps.

    Every 1/f s the demand is sampled (zero-order hold) and the counter c advances by
    e = sat(d − c, −1, 1). The driver sees a pulse of 5|e| V in the second half of the
    period and steps only if it crosses 2.5 V, i.e. if |e| > 0.5, in the direction of e.

    Args:
        demand_steps: (N,) the demand, steps.
        times: (N,) its times, s.
        rate: f, the controller's rate, Hz.
        t0: the run's start, s.
        t1: the run's end, s.

    Returns:
        step_times: (K,) times of the step edges, s, sorted.
        step_counts: (K,) driver step count k after each edge (integers, as float).
    """
    demand_steps = np.asarray(demand_steps, float)
    n = math.floor((t1 - 0.0) * rate) + 1
    sample_t = np.arange(n) / rate
    sample_t = sample_t[(sample_t >= t0 - 1e-12) | (np.arange(n) == 0)]
    sample_t[0] = max(sample_t[0], t0)
    d = np.interp(sample_t, times, demand_steps, left=np.nan, right=np.nan)
    d = _extrapolate(sample_t, times, demand_steps, d)
    c, k, out_t, out_k = 0.0, 0, [], []
    for tk, dk in zip(sample_t, d):
        e = min(max(dk - c, -1.0), 1.0)
        if abs(e) > 0.5:
            k += 1 if e > 0 else -1
            edge = tk + 0.5 / rate
            if edge < t1:
                out_t.append(edge)
                out_k.append(k)
        c += e
    return np.asarray(out_t, float), np.asarray(out_k, float)


def _extrapolate(t, xp, fp, values):
    """Fill NaNs of ``values`` by linear extrapolation from the two end samples (From Workspace default)."""
    lo, hi = t < xp[0], t > xp[-1]
    slope_lo = (fp[1] - fp[0]) / (xp[1] - xp[0])
    slope_hi = (fp[-1] - fp[-2]) / (xp[-1] - xp[-2])
    values = np.where(lo, fp[0] + slope_lo * (t - xp[0]), values)
    return np.where(hi, fp[-1] + slope_hi * (t - xp[-1]), values)
