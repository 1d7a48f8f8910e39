"""Control design on the differentiable model: linearisation, trajectory optimisation, length feedback, MPC.

What is here, in the order a design uses it:

* :func:`linearize` — the state-space model (A, B, C, D) of pressure demand → length (forward drive) or
  step command → length (stepper) about an operating point, from exact JAX Jacobians of the fast
  configuration's vector field, as a python-control ``StateSpace`` (``sys.A`` … work with ``scipy.signal``).
* :func:`optimize_profile` — the pressure-demand profile (piecewise linear on fixed knots) that makes the
  robot follow a desired length, by Levenberg–Marquardt with forward-mode Jacobians through
  :func:`growjax.simulate` (all knots in one merged sensitivity solve), inside the demand box [0, p_max].
  For the stepper drive (integer commands) an open-loop step schedule is found on the model without gradients:
  :func:`optimize_steps` searches the lead of a schedule read off the target, :func:`plan_steps` replays the
  steps the tuned closed-loop step controller issues on the model.
* :func:`run_closed_loop` — a sampled-data length controller around either configuration of the plant:
  :class:`LengthPID` (forward drive, outer loop over the pressure PID, with the optimised profile as
  feed-forward), :class:`StepController` (stepper: back-and-forth steps on the length error) and
  :class:`MPC` (forward drive; nonlinear, Gauss–Newton on the fast model from the current state).
* :func:`tune_pid` — gains by gradient descent on the closed-loop tracking cost, optionally averaged over
  parameter draws (robust design, :func:`parameter_draws`).

The plant of a closed loop is integrated tick by tick from its state: the fast configuration with its
own Rosenbrock integrator (:func:`growjax._rosenbrock.integrate`), the reference with diffrax Kvaerno5 at
its default rtol 1e-6, each from its own vector field, so the controller is evaluated on the model it was
not designed on. All quantities SI: lengths m, pressures Pa, times s.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import effects as fx
from growjax import fast_model as fm
from growjax import reference_model as rm
from growjax._rosenbrock import evaluate, integrate

PRESSURE_MARGIN = 0.9  # demand ceiling as a fraction of the membrane limit


# -- targets and limits ---------------------------------------------------------------------------------


class Target(NamedTuple):
    """A desired length: ``time`` (T,) s, ``length`` (T,) m, ``catheter`` (T,) m (catheter in contact; 0 if unknown)."""

    time: np.ndarray
    length: np.ndarray
    catheter: np.ndarray

    def at(self, t):
        """Desired length (m) at times ``t`` (s), held at the ends."""
        return np.interp(t, self.time, self.length)


def target_from_experiment(exp, t_end: float = 10.0) -> Target:
    """The target of an experiment: its ``desired_length_m`` column, else the measured ``robot_length_m``."""
    exp = exp.window(t_end + 1e-9)
    col = "desired_length_m" if "desired_length_m" in exp else "robot_length_m"
    if col not in exp:
        raise ValueError("the data need a desired_length_m or robot_length_m column to serve as the target")
    cath = exp["catheter_length_m"] if "catheter_length_m" in exp else np.zeros_like(exp.time)
    return Target(np.asarray(exp.time, float), np.asarray(exp[col], float), np.asarray(cath, float))


def ramp_with_pauses(t_end=3.0, dt=0.01, start=0.010, speed=5e-3, move=0.5, pause=0.5) -> Target:
    """A ramp at ``speed`` (m/s) for ``move`` s, then a pause of ``pause`` s, repeated; from ``start`` m."""
    t = np.arange(dt, t_end + 1e-9, dt)
    period = move + pause
    moving = np.minimum(np.mod(t, period), move) + move * np.floor(t / period)
    return Target(t, start + speed * moving, np.zeros_like(t))


def step_sequence(t_end=3.0, dt=0.01, start=0.010, height=2e-3, every=1.0, rise=0.3) -> Target:
    """Steps of ``height`` m every ``every`` s, each a ``rise`` s ramp (a physical robot cannot jump)."""
    t = np.arange(dt, t_end + 1e-9, dt)
    k = np.floor(t / every)
    frac = np.clip((t - k * every) / rise, 0.0, 1.0)
    return Target(t, start + height * (k + frac), np.zeros_like(t))


class Limits(eqx.Module):
    """Actuator and membrane limits a design must respect.

    Attributes:
        max_demand: Pa, ceiling of the pressure demand (a margin below the membrane limit).
        pressure_limit: Pa, membrane limit (paper eq. 8).
        syringe_stroke: m, travel of the syringe plungers.
        max_syringe_speed: m/s, platform speed the pump can give.
        max_step_rate: steps/s of the stepper drive.
    """

    max_demand: float
    pressure_limit: float
    syringe_stroke: float
    max_syringe_speed: float = 5e-3
    max_step_rate: float = 100.0


def limits(params, margin: float = PRESSURE_MARGIN, **kw) -> Limits:
    """The :class:`Limits` of ``params``: demand ceiling ``margin`` × membrane limit."""
    plim = float(gj.pressure_limit(params.robot))
    return Limits(margin * plim, plim, float(params.pump.syringe_stroke), **kw)


def plant_params(drive: str, target: Target | None = None, base=None):
    """Reference parameters of ``drive`` with the robot starting at the target's first length (m)."""
    p = base if base is not None else gj.reference(drive)
    if target is not None:
        p = gj.replace(p, initial_length=float(target.length[0]))
    return p


def step_length(params) -> float:
    """Robot length per full motor step, m: lead·(step angle/2π)·n A_s / A_r (3.1 mm for the published rig)."""
    pump, motor = params.pump, params.motor
    syringe = float(pump.lead) * float(motor.step_angle) / (2 * math.pi)
    return syringe * pump.n_syringes * float(pump.syringe_area) / float(params.robot.area)


def rmse(t, length, target: Target, t_start: float = 0.0) -> float:
    """RMS of (length − target) over the samples at t ≥ ``t_start``, m (NaN if a sample is not finite)."""
    t, length = np.asarray(t), np.asarray(length)
    keep = t >= t_start - 1e-12
    return float(np.sqrt(np.mean((length[keep] - target.at(t[keep])) ** 2)))


# -- microstepping driver (stepper) ------------------------------------------------------------------------


def with_microstepping(params, on: bool = True):
    """``params`` with the stepper's driver swapped for the sine–cosine microstepping one (both configurations;
    :func:`growjax.motor.winding_voltages`): the step command may then be any real number."""
    return eqx.tree_at(lambda p: p.motor, params, dataclasses.replace(params.motor, microstepping=on))


# -- the plant, integrated from any state -------------------------------------------------------------------


class Plant(eqx.Module):
    """A configuration of the model as a plant: (params with effects applied, config, prepared constants).

    ``microstep`` swaps the stepper's full-step driver for the microstepping one (:func:`with_microstepping`).
    """

    params: object
    config: gj.Config = eqx.field(static=True)
    prep: object

    @classmethod
    def make(cls, params, config: gj.Config, microstep: bool = False) -> Plant:
        if microstep and config.drive != "inverse":
            raise ValueError("microstepping is a driver of the stepper (inverse) drive")
        params = fx.apply_all(with_microstepping(params) if microstep else params)
        prep = (fm.prepare if config.fidelity == "fast" else rm.prepare)(params, config)
        return cls(params, config, prep)

    @property
    def microstep(self) -> bool:
        """Does the stepper's driver microstep?"""
        return bool(self.params.motor.microstepping)

    def initial_state(self):
        return (fm.initial_state if self.config.fidelity == "fast" else rm.initial_state)(self.params, self.config)

    def scales(self):
        mod = fm if self.config.fidelity == "fast" else rm
        return jnp.asarray(mod.layout(self.params, self.config.drive)[1])

    def field(self, t, y, inputs):
        """Scaled state rates (the solver's field)."""
        mod = fm if self.config.fidelity == "fast" else rm
        return mod.vector_field(t, y, (self.params, inputs, self.config, self.prep))

    def outputs(self, t, y, inputs):
        """(length m, sensed pressure Pa, syringe displacement m) of a scaled state."""
        if self.config.fidelity == "fast":
            rates = fm._rates(t, y * self.scales(), self.params, inputs, self.config, self.prep)
            length, pressure, _, x_p, _ = rates[1]
        else:
            length, pressure, _, x_p, _ = rm._outputs(t, y, self.params, inputs, self.config, self.prep)
        return length, pressure, x_p

    def advance(self, y, inputs, ta, tb, ts, knots=None):
        """Integrate from state ``y`` at ``ta`` to ``tb`` (s) → (state at tb, outputs at ``ts`` (S,) each, status).

        ``knots``: times (s) inside the interval where the inputs' slope breaks (stepped onto).
        """
        rtol, atol = self.config.tolerances
        ts = jnp.clip(ts, ta, tb)  # rounding of ta + k·dt must not leave the interval
        if self.config.fidelity == "fast":
            breaks = jnp.full((1,), tb + 1.0) if knots is None else jnp.concatenate([knots, jnp.full((1,), tb + 1.0)])
            run = integrate(self.field, y, ta, tb, args=inputs, breaks=breaks,
                            jumps=jnp.zeros(breaks.shape, bool), rtol=rtol, atol=atol, max_steps=400, dtmax=0.05)
            ys = evaluate(run.steps, ts)[:, 0]
            y_end, status = run.y_final[0], run.status
        else:
            import diffrax

            ctrl = diffrax.PIDController(rtol=rtol, atol=atol, pcoeff=0.3, icoeff=0.4, dtmax=0.05,
                                         step_ts=knots)
            sol = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, z, a: self.field(t, z, inputs)), diffrax.Kvaerno5(),
                                      ta, tb, 1e-6, y, saveat=diffrax.SaveAt(ts=ts, t1=True),
                                      stepsize_controller=ctrl, max_steps=20_000, throw=False)
            ys, y_end = sol.ys[:-1], sol.ys[-1]
            status = jnp.where(sol.result == diffrax.RESULTS.successful, 0, 2)
        out = jax.vmap(lambda t, z: self.outputs(t, z, inputs))(ts, ys)
        return y_end, out, status


def _segment_inputs(catheter, ta, tb, ua, ub, steps):
    """Inputs of one tick: the demand ramps from ``ua`` at ``ta`` to ``ub`` at ``tb`` (first-order hold)."""
    return gj.Inputs(catheter_length=catheter, pressure_demand=gj.Sampled(jnp.stack([ta, tb]), jnp.stack([ua, ub])),
                     steps=gj.Constant(steps))


def catheter_signal(target: Target):
    return gj.Sampled(np.asarray(target.time, float), np.asarray(target.catheter, float))


# -- linearisation -----------------------------------------------------------------------------------------


def operating_point(params, drive: str = "forward", pressure: float = 150e3, length: float | None = None,
                    catheter: float = 0.0, steps: float = 0.0, settle: float = 1.0, microstep: bool = True):
    """(plant, scaled state, inputs) at an operating point.

    Forward drive: the state after ``settle`` s at constant demand ``pressure`` (Pa): growing at a steady
    rate above the yield pressure, holding below it. Inverse drive: held at step command ``steps``.
    ``length`` (m) sets the robot length of the point (default: where the settling run ends).
    """
    config = gj.Config(drive=drive, t1=settle)
    plant = Plant.make(params, config, microstep=microstep and drive == "inverse")
    inputs = gj.Inputs(catheter_length=gj.Constant(catheter), pressure_demand=gj.Constant(pressure),
                       steps=gj.Constant(steps))
    y0 = plant.initial_state()
    y, _, _ = jax.jit(lambda y: plant.advance(y, inputs, config.t0, settle, jnp.asarray([settle])))(y0)
    if length is not None:
        i = fm.layout(plant.params, drive)[0].index("robot_displacement")
        now = float(plant.outputs(settle, y, inputs)[0])
        y = y.at[i].add((length - now) / plant.scales()[i])
    return plant, y, inputs


def linearize(params=None, drive: str = "forward", pressure: float = 150e3, length: float | None = None,
              catheter: float = 0.0, steps: float = 0.0, settle: float = 1.0):
    """Linear model of demand → length about an operating point, as a ``control.StateSpace``.

    Forward drive: input the pressure demand (Pa), output the robot length (m); operating point after
    ``settle`` s at demand ``pressure`` (growing above the yield pressure, holding below). Inverse drive:
    input the step command (steps, continuous: a microstepping driver, :func:`with_microstepping`),
    output the length, held at ``steps``. States are the fast configuration's scaled states.
    A, B, C from exact Jacobians (``jax.jacfwd``) of the vector field; D = 0. The operating point
    (state, rates, whether it grows) is attached as ``sys.operating_point``.
    """
    import control

    params = params if params is not None else gj.reference(drive)
    plant, y, inputs = operating_point(params, drive, pressure, length, catheter, steps, settle)
    t = jnp.asarray(settle)

    def with_u(u):
        return (eqx.tree_at(lambda i: i.pressure_demand, inputs, gj.Constant(u)) if drive == "forward"
                else eqx.tree_at(lambda i: i.steps, inputs, gj.Constant(u)))

    u0 = jnp.asarray(pressure if drive == "forward" else steps, float)
    f = lambda y, u: plant.field(t, y, with_u(u))
    g = lambda y, u: plant.outputs(t, y, with_u(u))[0]
    a = np.asarray(jax.jacfwd(f, 0)(y, u0))
    b = np.asarray(jax.jacfwd(f, 1)(y, u0))[:, None]
    c = np.asarray(jax.jacfwd(g, 0)(y, u0))[None, :]
    d = np.asarray(jax.jacfwd(g, 1)(y, u0)).reshape(1, 1)
    names = list(fm.layout(plant.params, drive)[0])
    sys = control.ss(a, b, c, d, inputs=["pressure_demand" if drive == "forward" else "step_command"],
                     outputs=["length"], states=names)
    rates = np.asarray(f(y, u0))
    i = names.index("robot_displacement")
    sys.operating_point = {"state": np.asarray(y), "input": float(u0), "rates": rates,
                           "length_m": float(g(y, u0)), "pressure_Pa": float(plant.outputs(t, y, with_u(u0))[1]),
                           "growth_speed_m_s": float(rates[i] * plant.scales()[i]),
                           "growing": bool(rates[i] * plant.scales()[i] > 1e-5)}
    return sys


# -- open-loop trajectory optimisation ------------------------------------------------------------------------


class KnotProfile(gj.Sampled):
    """A piecewise-linear demand on fixed knots: every interior knot is declared a slope break, so the
    solvers' breaks do not depend on the (optimised, traced) values."""

    def kink_times(self, t0, t1, threshold: float = 0.0):
        t = np.asarray(self.times, float)
        return t[(t > t0) & (t < t1)]


class ProfileResult(NamedTuple):
    knots: np.ndarray  # (K,) s
    demand: np.ndarray  # (K,) Pa
    cost_history: list
    rmse_m: float  # on the configuration optimised on
    wall_s: float


def _profile_inputs(target: Target, knots, values):
    return gj.Inputs(catheter_length=catheter_signal(target), pressure_demand=KnotProfile(knots, values))


def optimize_profile(params, target: Target, t1: float | None = None, knot_dt: float = 0.2,
                     iterations: int = 15, lim: Limits | None = None, smooth: float = 1e-3,
                     initial: float = 120e3, config: gj.Config | None = None, lead: float = 0.0) -> ProfileResult:
    """The forward drive's pressure-demand profile (piecewise linear, knots every ``knot_dt`` s) that makes the
    length follow ``target``, by Levenberg–Marquardt on the tracking residuals.

    Residuals: length error on the target's grid (mm), ``smooth``·knot differences (per 10 kPa), and the sensed
    pressure's excess over ``lim.max_demand`` (per kPa); the knots are kept in [0, ``lim.max_demand``]
    (projection). Jacobians by forward mode through :func:`growjax.simulate` (all knots in one solve).
    """
    t0w = time.perf_counter()
    lim = lim or limits(params)
    t1 = t1 if t1 is not None else float(target.time[-1])
    config = config or gj.Config(t1=t1, adjoint="forward")
    knots = np.arange(0.0, t1 + knot_dt - 1e-9, knot_dt)
    ts = target.time[(target.time >= config.t0) & (target.time <= t1)]
    ref = jnp.asarray(target.at(ts))
    breaks = gj.input_breaks(_profile_inputs(target, knots, np.full(knots.size, initial)), config)
    scale = 1e5

    def residuals(x):
        values = x * scale
        tr = gj.simulate(params, _profile_inputs(target, knots, values), config, ts=ts, breaks=breaks)
        err = (tr.length - ref) / 1e-3
        over = jax.nn.relu(tr.pressure - lim.max_demand) / 1e3
        return jnp.concatenate([err, np.sqrt(smooth) * jnp.diff(x) * 10.0, over])

    res = jax.jit(residuals)
    jac = jax.jit(jax.jacfwd(residuals))
    hi = lim.max_demand / scale
    x = np.full(knots.size, initial / scale)
    if lead == 0.0:  # a first guess from the target's speed: demand rises with the growth speed needed
        speed = np.gradient(target.at(knots + knot_dt), knots)
        x = np.clip(0.6 + 12.0 * np.maximum(speed, 0.0) / 1e-2 * 0.1, 0.0, hi)
    r = np.asarray(res(jnp.asarray(x)))
    cost = float(np.sum(np.nan_to_num(r, nan=1e3) ** 2))
    history, mu = [cost], 1e-2
    for _ in range(iterations):
        j = np.nan_to_num(np.asarray(jac(jnp.asarray(x))))
        g, h = j.T @ np.nan_to_num(r, nan=1e3), j.T @ j
        for _ in range(6):  # raise the damping until the step lowers the cost
            step = np.linalg.solve(h + mu * (np.diag(np.diag(h)) + 1e-9 * np.eye(x.size)), -g)
            x_new = np.clip(x + step, 0.0, hi)
            r_new = np.asarray(res(jnp.asarray(x_new)))
            c_new = float(np.sum(np.nan_to_num(r_new, nan=1e3) ** 2)) if np.all(np.isfinite(r_new)) else np.inf
            if c_new < cost:
                x, r, cost, mu = x_new, r_new, c_new, max(mu / 3, 1e-6)
                break
            mu *= 4
        history.append(cost)
    n = ts.size
    return ProfileResult(knots, x * scale, history, float(np.sqrt(np.mean((r[:n] * 1e-3) ** 2))),
                         time.perf_counter() - t0w)


def simulate_profile(params, target: Target, profile: ProfileResult, config: gj.Config):
    """The trajectory of the forward drive under an optimised profile (any configuration), on the target's grid."""
    ts = target.time[(target.time >= config.t0) & (target.time <= config.t1)]
    return gj.simulate(params, _profile_inputs(target, profile.knots, profile.demand), config, ts=ts)


def step_commands(params, target: Target, rate: float, lead: float, t1: float, lim: Limits | None = None,
                  microsteps: int = 1):
    """Open-loop stepper command: (tick times (s), step counts) = round(demand(t + lead)·microsteps)/microsteps
    at ``rate`` Hz (≤ ``lim.max_step_rate``), at most one step per tick, back steps included."""
    lim = lim or limits(params)
    ticks = np.arange(0.0, t1, 1.0 / rate)
    demand = (target.at(ticks + lead) - target.length[0]) / step_length(params)
    if rate > lim.max_step_rate:
        raise ValueError(f"tick rate {rate} Hz exceeds the motor's step rate {lim.max_step_rate} steps/s")
    per_tick = 1.0  # one step per tick: a jump of two or more full steps at one edge makes the rotor skip
    k, counts = 0.0, []
    for d in demand:
        k += float(np.clip(np.round((d - k) * microsteps) / microsteps, -per_tick, per_tick))
        counts.append(k)
    return ticks, np.asarray(counts)


def optimize_steps(params, target: Target, t1: float, rate: float = 50.0, leads=None,
                   config: gj.Config | None = None):
    """The open-loop step schedule (integer steps: a search over the lead time, not gradients) of the stepper
    drive minimising the length RMSE on ``config`` (default fast). → (best lead s, RMSE m, ticks, counts)."""
    config = config or gj.Config(drive="inverse", t1=t1)
    leads = np.linspace(0.0, 0.4, 9) if leads is None else leads
    ts = target.time[(target.time >= config.t0) & (target.time <= t1)]
    best = None
    for lead in leads:
        ticks, counts = step_commands(params, target, rate, lead, t1)
        tr = simulate_steps(params, target, ticks, counts, config, ts)
        e = rmse(ts, tr.length, target)
        if best is None or e < best[1]:
            best = (float(lead), e, ticks, counts)
    return best


def plan_steps(params, target: Target, t1: float, microsteps: int = 1, controller: StepController | None = None):
    """The open-loop step schedule planned on the fast model: the tuned closed-loop :class:`StepController`
    (``controller``, default :func:`tune_stepper`'s) runs on the model, and the step counts it issues there are
    the schedule, replayed on the robot without measuring it. The feedback acts on the model's length, so the
    plan inherits the controller's back steps and pressure gate but not its correction of model error.
    → (controller, RMSE m on the model, tick times (s), step counts)."""
    if controller is None:
        controller, _ = tune_stepper(params, target, t1, microsteps)
    plant = Plant.make(params, gj.Config(drive="inverse", t1=t1), microstep=microsteps > 1)
    res = run_closed_loop(plant, controller, target, t1, limits(params))
    return controller, res.rmse_m, np.asarray(res.tick_time, float), np.asarray(res.command, float)


def simulate_steps(params, target: Target, ticks, counts, config: gj.Config, ts):
    """Simulate the stepper drive under a step schedule (tick times, counts; changes only)."""
    change = np.concatenate([[counts[0] != 0], np.diff(counts) != 0])
    sched = gj.StepSchedule(jnp.asarray(ticks[change]), jnp.asarray(counts[change]))
    inputs = gj.Inputs(catheter_length=catheter_signal(target), steps=sched)
    return gj.simulate(params, inputs, config, ts=ts)


# -- feedback ---------------------------------------------------------------------------------------------------


class LengthPID(eqx.Module):
    """Sampled PI-D on length over the pressure loop (forward drive), with feed-forward and anti-windup.

    demand_k = clip(ff(t_k+1) + Kp e + Ki ∫e + Kd ė_f, 0, max_demand), e = L_ref(t_k) − L_k (m).
    Gains as log10 of SI values: Kp Pa/m, Ki Pa/(m·s), Kd Pa·s/m. ``ff``: (knots, values) of a demand profile.
    """

    log_gains: jax.Array  # (3,) log10(Kp, Ki, Kd)
    ff_knots: jax.Array
    ff_values: jax.Array
    dt: float = eqx.field(static=True, default=0.01)

    def gains(self):
        return 10.0 ** self.log_gains

    def init(self):
        return jnp.zeros(2)  # (integral of error m·s, filtered derivative m/s)

    def __call__(self, state, t, error, lim: Limits):
        kp, ki, kd = self.gains()
        integral, deriv = state
        ff = jnp.interp(t + self.dt, self.ff_knots, self.ff_values)
        raw = ff + kp * error + ki * integral + kd * deriv
        u = jnp.clip(raw, 0.0, lim.max_demand)
        saturated = (raw != u) & (jnp.sign(error) == jnp.sign(raw - u))
        new_integral = integral + jnp.where(saturated, 0.0, error * self.dt)
        return u, jnp.stack([new_integral, deriv])


class ClosedLoopResult(NamedTuple):
    time: np.ndarray  # (T,) s
    length: np.ndarray  # m
    pressure: np.ndarray  # Pa
    command: np.ndarray  # demand Pa (forward) or step count (inverse), per tick
    tick_time: np.ndarray  # s
    rmse_m: float
    pressure_limit_crossed: bool
    status: int
    step_s: np.ndarray | None = None  # controller compute time per tick (MPC), s


def _pid_loop(plant: Plant, pid: LengthPID, target_ts, target_len, catheter, lim: Limits, t1: float):
    """The PID closed loop as one ``lax.scan`` over ticks of ``pid.dt`` → (ts, length, pressure, demand, status)."""
    dt = pid.dt
    n = int(round(t1 / dt))  # noqa: RUF046 (t1 may be an array scalar)
    ticks = jnp.arange(n) * dt
    y0 = plant.initial_state()
    ref = lambda t: jnp.interp(t, target_ts, target_len)
    u0 = jnp.interp(0.0, pid.ff_knots, pid.ff_values)

    def tick(carry, ta):
        y, c, u_prev, length, e_prev = carry
        e = ref(ta) - length
        c = c.at[1].set(0.7 * c[1] + 0.3 * (e - e_prev) / dt)
        u, c = pid(c, ta, e, lim)
        tb = ta + dt
        inputs = _segment_inputs(catheter, ta, tb, u_prev, u, 0.0)
        y, (l, p, _), st = plant.advance(y, inputs, ta, tb, tb[None])
        return (y, c, u, l[0], e), (tb, l[0], p[0], u, st)

    l0 = plant.outputs(0.0, y0, _segment_inputs(catheter, 0.0, dt, u0, u0, 0.0))[0]
    carry = (y0, pid.init(), u0, l0, ref(0.0) - l0)
    _, out = jax.lax.scan(tick, carry, ticks)
    return out


def run_closed_loop(plant: Plant, controller, target: Target, t1: float, lim: Limits | None = None) -> ClosedLoopResult:
    """Run a length controller (:class:`LengthPID`, :class:`StepController` or :class:`MPC`) around ``plant``
    from rest over [0, t1] s, and score it against ``target`` (RMSE on the samples at t ≥ 0.01 s)."""
    lim = lim or limits(plant.params)
    cath = catheter_signal(target)
    if isinstance(controller, LengthPID):
        fn = eqx.filter_jit(_pid_loop)
        ts, length, pressure, u, st = fn(plant, controller, jnp.asarray(target.time), jnp.asarray(target.length),
                                         cath, lim, t1)
        ts, length, pressure = np.asarray(ts), np.asarray(length), np.asarray(pressure)
        return _score(ts, length, pressure, np.asarray(u), ts - controller.dt, target, lim, int(np.max(st)))
    return controller.run(plant, target, t1, lim, cath)


def _score(ts, length, pressure, command, ticks, target, lim, status, step_s=None) -> ClosedLoopResult:
    keep = ts >= 0.01 - 1e-12
    e = rmse(ts[keep], length[keep], target)
    crossed = bool(np.any(~np.isfinite(pressure)) or np.nanmax(pressure) > lim.pressure_limit)
    return ClosedLoopResult(ts, length, pressure, command, ticks, e if np.isfinite(e) else float("nan"), crossed,
                            status, step_s)


@eqx.filter_jit
def _step_segment(plant: Plant, cath, y, ta, k, dt: float, sub: int):
    """One tick of ``dt`` s at step command ``k`` from state ``y`` at ``ta``, saved at ``sub`` points (one compiled
    program per plant and tick, shared by every controller run on it: a tuning search compiles it once)."""
    tb = ta + dt
    ts = ta + dt * jnp.arange(1, sub + 1) / sub
    return plant.advance(y, _segment_inputs(cath, ta, tb, 0.0, 0.0, k), ta, tb, ts)


class StepController(eqx.Module):
    """Closed-loop step controller of the stepper drive: every 1/``rate`` s, step by round(e·microsteps)/microsteps
    (at most one full step per tick, back steps included) when the length error e (in steps, the target
    taken ``lead`` s ahead) exceeds ``deadband`` steps; no forward step while the sensed pressure is at or
    above ``pressure_gate`` (Pa): there the load torque would make the motor slip, and the step is lost."""

    rate: float = 20.0
    lead: float = 0.1
    deadband: float = 0.5
    microsteps: int = eqx.field(static=True, default=1)
    pressure_gate: float = float("inf")

    def run(self, plant: Plant, target: Target, t1: float, lim: Limits, cath) -> ClosedLoopResult:
        if self.microsteps > 1 and not plant.microstep:
            raise ValueError("microsteps > 1 needs a plant made with microstep=True")
        dt = 1.0 / self.rate
        sub = max(1, int(round(dt / 0.01)))  # noqa: RUF046 (rate may be an array scalar)
        ticks = np.arange(0.0, t1 - 1e-9, dt)
        if self.rate > lim.max_step_rate:
            raise ValueError(f"tick rate {self.rate} Hz exceeds the motor's step rate {lim.max_step_rate} steps/s")
        per_tick = 1.0  # at most one full step per tick (several at one edge make the rotor skip)
        s_len = step_length(plant.params)

        def seg(y, ta, k):
            return _step_segment(plant, cath, y, ta, k, dt, sub)

        y = plant.initial_state()
        length, pressure, _ = (float(v) for v in plant.outputs(0.0, y, _segment_inputs(cath, 0.0, dt, 0.0, 0.0, 0.0)))
        k = 0.0
        out_t, out_l, out_p, ks, status = [], [], [], [], 0
        for ta in ticks:
            e = (target.at(ta + self.lead) - length) / s_len
            if abs(e) > self.deadband / self.microsteps:
                step = float(np.clip(np.round(e * self.microsteps) / self.microsteps, -per_tick, per_tick))
                k += 0.0 if (step > 0 and pressure >= self.pressure_gate) else step
            y, (l, p, _), st = seg(y, jnp.asarray(ta), jnp.asarray(k))
            length, pressure = float(l[-1]), float(p[-1])
            status = max(status, int(st))
            out_t.append(ta + dt * np.arange(1, sub + 1) / sub)
            out_l.append(np.asarray(l))
            out_p.append(np.asarray(p))
            ks.append(k)
        ts = np.concatenate(out_t)
        return _score(ts, np.concatenate(out_l), np.concatenate(out_p), np.asarray(ks), ticks, target, lim, status)


class MPC(eqx.Module):
    """Nonlinear model-predictive length control of the forward drive on the fast configuration.

    Every ``dt`` s: from the current state estimate, choose the demand at the next ``horizon`` knots (first-order
    hold, in [0, max_demand]) minimising Σ (L − L_ref)²/(1 mm)² + ``w_move``·Σ(Δu/10 kPa)² + pressure excess over
    the ceiling, by ``iterations`` Gauss–Newton steps (Jacobian: one batched forward-difference solve of the
    fast model), warm-started from the last plan; apply the first knot. On a plant of another configuration the
    state estimate is the fast model run alongside, with its length and pressure reset to the measured ones.
    """

    dt: float = 0.1
    horizon: int = 5
    w_move: float = 0.05
    iterations: int = 2
    samples: int = 4  # cost samples per tick

    def _predictor(self, model: Plant, cath):
        n, m = self.horizon, self.samples
        hdt = self.dt

        def predict(y, ta, u_now, plan):
            knots_t = ta + hdt * jnp.arange(n + 1)
            inputs = gj.Inputs(catheter_length=cath, pressure_demand=gj.Sampled(knots_t, jnp.concatenate([u_now[None], plan])))
            ts = ta + hdt * jnp.arange(1, n * m + 1) / m
            _, (l, p, _), _ = model.advance(y, inputs, ta, ta + n * hdt, ts, knots=knots_t[1:-1])
            return l, p

        return predict

    def run(self, plant: Plant, target: Target, t1: float, lim: Limits, cath) -> ClosedLoopResult:
        model = plant
        if plant.config.fidelity != "fast":  # the internal model: the fast configuration of the same parameters
            cfg = gj.Config(drive="forward", t1=t1)
            model = Plant(plant.params, cfg, fm.prepare(plant.params, cfg))
        predict = self._predictor(model, cath)
        n, m, scale = self.horizon, self.samples, 1e4
        hi = lim.max_demand

        @jax.jit
        def plan_step(y, ta, u_now, plan, ref):
            def resid(x):
                l, p = predict(y, ta, u_now, x * scale)
                du = jnp.diff(jnp.concatenate([u_now[None] / scale, x]))
                return jnp.concatenate([(l - ref) / 1e-3, jnp.sqrt(self.w_move) * du,
                                        jax.nn.relu(p - hi) / 1e3])

            x = plan / scale
            eps = 0.05  # 500 Pa
            for _ in range(self.iterations):
                pert = jnp.concatenate([x[None], x[None] + eps * jnp.eye(n)])
                rs = jax.vmap(resid)(pert)
                r0, j = rs[0], ((rs[1:] - rs[0]) / eps).T
                step = jnp.linalg.solve(j.T @ j + 1e-3 * jnp.eye(n), -j.T @ r0)
                x = jnp.clip(x + step, 0.0, hi / scale)
            return x * scale

        sub = max(1, int(round(self.dt / 0.01)))  # noqa: RUF046 (dt may be an array scalar)

        @jax.jit
        def seg(y, ta, ua, ub):
            tb = ta + self.dt
            ts = ta + self.dt * jnp.arange(1, sub + 1) / sub
            return plant.advance(y, _segment_inputs(cath, ta, tb, ua, ub, 0.0), ta, tb, ts)

        @jax.jit
        def seg_model(y, ta, ua, ub):
            tb = ta + self.dt
            return model.advance(y, _segment_inputs(cath, ta, tb, ua, ub, 0.0), ta, tb, tb[None])[0]

        observer = plant.config.fidelity != "fast"
        ticks = np.arange(0.0, t1 - 1e-9, self.dt)
        y = plant.initial_state()
        y_hat = model.initial_state()
        u_now = 0.0
        plan = jnp.full(n, 1.2e5)
        out_t, out_l, out_p, us, step_s, status = [], [], [], [], [], 0
        meas = None
        for ta in ticks:
            ref = target.at(ta + self.dt * np.arange(1, n * m + 1) / m)
            est = y if not observer else y_hat
            if observer and meas is not None:
                est = _reset_estimate(model, y_hat, ta, meas)
            start = time.perf_counter()
            plan = jax.block_until_ready(plan_step(est, jnp.asarray(ta), jnp.asarray(u_now), plan, jnp.asarray(ref)))
            step_s.append(time.perf_counter() - start)
            u_next = float(plan[0])
            y, (l, p, _), st = seg(y, jnp.asarray(ta), jnp.asarray(u_now), jnp.asarray(u_next))
            if observer:
                y_hat = seg_model(est, jnp.asarray(ta), jnp.asarray(u_now), jnp.asarray(u_next))
                meas = (float(l[-1]), float(p[-1]))
            status = max(status, int(st))
            out_t.append(ta + self.dt * np.arange(1, sub + 1) / sub)
            out_l.append(np.asarray(l))
            out_p.append(np.asarray(p))
            us.append(u_next)
            u_now = u_next
            plan = jnp.concatenate([plan[1:], plan[-1:]])
        ts = np.concatenate(out_t)
        return _score(ts, np.concatenate(out_l), np.concatenate(out_p), np.asarray(us), ticks, target, lim, status,
                      np.asarray(step_s))


def _reset_estimate(model: Plant, y_hat, t, measured):
    """The fast model's state with its length and chamber pressure set to the measured (length m, pressure Pa)."""
    length, pressure = measured
    names = fm.layout(model.params, "forward")[0]
    s = model.scales()
    dummy = gj.Inputs(catheter_length=gj.Constant(0.0))
    now = float(model.outputs(t, y_hat, dummy)[0])
    i = names.index("robot_displacement")
    y = y_hat.at[i].add((length - now) / s[i])
    wall = y[names.index("wall_strain")] * s[names.index("wall_strain")]
    stored = fm.stored_volume(model.params, pressure, wall)
    return y.at[0].set(stored / s[0])


# -- tuning -------------------------------------------------------------------------------------------------------


def parameter_draws(n: int, seed: int = 0, posterior: str | None = None, base=None, rel_sd: float = 0.05,
                    names=None):
    """Parameter sets as {name: (n,) array}.

    From an ArviZ posterior file: joint draws (picked at random, seeded) of its variables that name a model
    parameter (``names`` restricts them; noise scales such as σ and derived sites are skipped), so the
    draws keep the posterior's correlations. With no file: Gaussian around the point estimate of ``base``
    with relative s.d. ``rel_sd`` (seeded; a stand-in when no posterior is at hand), ``names`` default ("Y",).
    """
    rng = np.random.default_rng(seed)
    base = base if base is not None else gj.reference("forward")
    if posterior:
        import arviz as az

        post = az.from_netcdf(posterior).posterior
        wanted = list(names) if names is not None else [k for k in post.data_vars if _is_parameter(base, k)]
        flat = {k: np.asarray(post[k]).ravel() for k in wanted if k in post}
        if not flat:
            raise ValueError(f"{posterior} has none of the model parameters {wanted or list(post.data_vars)}")
        size = next(iter(flat.values())).size
        idx = rng.choice(size, size=n, replace=n > size)
        return {k: v[idx] for k, v in flat.items()}
    return {k: float(gj.get(base, k)) * (1.0 + rel_sd * rng.standard_normal(n)) for k in (names or ("Y",))}


def _is_parameter(base, name: str) -> bool:
    try:
        gj.get(base, name)
    except ValueError:
        return False
    return True


def _batched_params(base, draws: dict):
    """One Parameters pytree with the drawn leaves batched (leading axis n)."""
    return gj.replace(base, **{k: jnp.asarray(v) for k, v in draws.items()})


class TuneResult(NamedTuple):
    log_gains: np.ndarray
    gains: dict
    cost_history: list
    wall_s: float


def pid_cost_fn(base, target: Target, t1: float, pid: LengthPID, draws: dict | None = None,
                lim: Limits | None = None, config: gj.Config | None = None):
    """J(log_gains) = mean over parameter draws of the squared length RMSE (mm²) of the PID closed loop on the
    fast configuration (+ a penalty on pressure above the membrane limit); jitted, vmapped over draws."""
    lim = lim or limits(base)
    config = config or gj.Config(t1=t1)
    cath = catheter_signal(target)

    def one(params, log_gains):
        plant = Plant.make(params, config)
        ctrl = eqx.tree_at(lambda c: c.log_gains, pid, log_gains)
        ts, length, pressure, _, _ = _pid_loop(plant, ctrl, jnp.asarray(target.time), jnp.asarray(target.length),
                                              cath, lim, t1)
        err = (length - jnp.interp(ts, jnp.asarray(target.time), jnp.asarray(target.length))) / 1e-3
        over = jax.nn.relu(pressure - lim.pressure_limit) / 1e3
        return jnp.mean(jnp.nan_to_num(err, nan=1e2) ** 2) + jnp.mean(over**2)

    if draws:
        batched = _batched_params(base, draws)
        axes = _draw_axes(base, draws)
        fn = lambda lg: jnp.mean(jax.vmap(one, in_axes=(axes, None))(batched, lg))
    else:
        fn = lambda lg: one(base, lg)
    return jax.jit(fn)


def _draw_axes(base, draws):
    """in_axes of a parameter pytree whose drawn leaves carry a leading batch axis."""
    return gj.replace(jax.tree_util.tree_map(lambda _: None, base), **{k: 0 for k in draws})


def tune_pid(cost, log_gains, iterations: int = 10, step: float = 0.3, fd: float = 0.02) -> TuneResult:
    """Gradient descent on ``cost(log_gains)`` with backtracking; the gradient by central differences in
    log-gain space (``fd`` decades, a smoothed slope: at tuned high gains the closed loop's tangent grows along a
    10 s run and the cost is rough on small scales, so exact forward-mode derivatives diverge there; see
    benchmarks/control_gradient.py), all 2d+1 evaluations of one iteration batched."""
    start = time.perf_counter()
    x = np.asarray(log_gains, float)
    d = x.size
    batch = jax.jit(jax.vmap(cost))
    c = float(cost(jnp.asarray(x)))
    hist = [c]
    for _ in range(iterations):
        pts = np.concatenate([x[None] + fd * np.eye(d), x[None] - fd * np.eye(d)])
        vals = np.asarray(batch(jnp.asarray(pts)))
        g = (vals[:d] - vals[d:]) / (2 * fd)
        if not np.all(np.isfinite(g)) or np.linalg.norm(g) == 0:
            break
        direction = -g / np.linalg.norm(g)
        s = step
        trials = np.stack([x + s * direction * 0.5**i for i in range(4)])
        tv = np.asarray(batch(jnp.asarray(trials)))
        best = int(np.nanargmin(np.where(np.isfinite(tv), tv, np.inf)))
        if not tv[best] < c:
            step *= 0.25
            hist.append(c)
            continue
        x, c = trials[best], float(tv[best])
        step = min(step * (1.5 if best == 0 else 1.0), 1.0) if best == 0 else s * 0.5**best
        hist.append(c)
    kp, ki, kd = 10.0 ** x
    return TuneResult(x, {"Kp_Pa_per_m": kp, "Ki_Pa_per_m_s": ki, "Kd_Pa_s_per_m": kd}, hist,
                      time.perf_counter() - start)


# -- command line -----------------------------------------------------------------------------------------------


DEFAULT_LOG_GAINS = (7.0, 7.0, 4.5)  # Kp 1e7 Pa/m (10 kPa per mm), Ki 1e7 Pa/(m s), Kd 3e4 Pa s/m


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``growjax control DATA``."""
    parser.add_argument("data", nargs="?", help="experiment CSV (or folder); target: desired_length_m, else robot_length_m")
    parser.add_argument("--drive", choices=["forward", "inverse"], default="forward")
    parser.add_argument("--method", choices=["open-loop", "feedback", "mpc"], default="feedback")
    parser.add_argument("--robust", metavar="POSTERIOR.nc", help="tune on the cost averaged over posterior draws")
    parser.add_argument("--draws", type=int, default=8, help="posterior draws to tune on (--robust; default 8)")
    parser.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    parser.add_argument("--iterations", type=int, default=10, help="optimiser / tuning iterations (default 10)")
    parser.add_argument("--microsteps", type=int, default=1,
                        help="stepper driver microsteps (1: the shipped full-step driver)")
    parser.add_argument("--evaluate", choices=["fast", "reference"], default="reference",
                        help="configuration the tracking RMSE is evaluated on (default reference)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="out", help="output folder (control.png)")
    parser.add_argument("--json", help="also write the JSON summary to this file")


def command(args) -> dict:
    """Run ``growjax control``: design on the fast model, evaluate on ``--evaluate``, write a figure, return JSON."""
    from growjax import experiment as ex
    from growjax.cli import default_data_path

    data = Path(args.data) if args.data else default_data_path()
    target = target_from_experiment(ex.read(data), args.t_end)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = design(target, args.drive, args.method, args.t_end, robust=args.robust, n_draws=args.draws,
                     iterations=args.iterations, microsteps=args.microsteps, evaluate_on=args.evaluate,
                     seed=args.seed, figure=out / "control.png")
    return {"data": str(data), **summary}


def design(target: Target, drive: str, method: str, t1: float, robust: str | None = None, n_draws: int = 8,
           iterations: int = 10, microsteps: int = 1, evaluate_on: str = "reference", seed: int = 0,
           figure=None, knot_dt: float = 0.2) -> dict:
    """One design (drive × method) for ``target`` over [0, t1] s, evaluated on ``evaluate_on``. → JSON-ready dict."""
    params = plant_params(drive, target)
    lim = limits(params)
    evaluate_cfg = gj.Config(fidelity=evaluate_on, drive=drive, t1=t1)
    summary: dict = {"drive": drive, "method": method, "t_end_s": t1, "evaluated_on": evaluate_on,
                     "pressure_limit_Pa": lim.pressure_limit, "max_demand_Pa": lim.max_demand}
    start = time.perf_counter()
    if drive == "inverse":
        if method == "mpc":
            raise ValueError("the MPC is designed for the forward drive; use --method feedback for the stepper")
        if method == "open-loop":
            # schedules made on the fast model; the one tracking best there is run blind
            ctrl, plan_rmse, ticks, counts = plan_steps(params, target, t1, microsteps)
            on_model, planned_by = {"step controller on the model": plan_rmse}, "step controller on the model"
            if microsteps == 1:  # the lead search reads a full-step schedule off the target
                lead, lead_rmse, lead_ticks, lead_counts = optimize_steps(params, target, t1)
                on_model["lead search"] = lead_rmse
                summary["lead_search_lead_s"] = lead
                if lead_rmse < plan_rmse:
                    planned_by, ticks, counts = "lead search", lead_ticks, lead_counts
            summary["design_s"] = time.perf_counter() - start
            ts = target.time[(target.time >= evaluate_cfg.t0) & (target.time <= t1)]
            driven = with_microstepping(params) if microsteps > 1 else params
            tr = simulate_steps(driven, target, ticks, counts, evaluate_cfg, ts)
            res = _score(ts, np.asarray(tr.length), np.asarray(tr.pressure), counts, ticks, target, lim,
                         int(tr.status))
            summary["profile"] = {"planned_by": planned_by, "model_rmse_m": on_model,
                                  "controller": {"rate_Hz": ctrl.rate, "lead_s": ctrl.lead,
                                                 "microsteps": ctrl.microsteps},
                                  "tick_s": ticks.tolist(), "steps": counts.tolist()}
        else:
            ctrl, _ = tune_stepper(params, target, t1, microsteps)
            summary["design_s"] = time.perf_counter() - start
            res = run_closed_loop(Plant.make(params, evaluate_cfg, microstep=microsteps > 1), ctrl, target, t1, lim)
            gate = ctrl.pressure_gate if math.isfinite(ctrl.pressure_gate) else None  # JSON has no infinity
            summary["gains"] = {"rate_Hz": ctrl.rate, "lead_s": ctrl.lead, "deadband_steps": ctrl.deadband,
                                "microsteps": ctrl.microsteps, "pressure_gate_Pa": gate}
    else:
        prof = optimize_profile(params, target, t1, knot_dt=knot_dt, iterations=iterations, lim=lim)
        summary["profile_optimisation_s"] = prof.wall_s
        summary["profile"] = {"knots_s": prof.knots.tolist(), "demand_Pa": prof.demand.tolist()}
        if method == "open-loop":
            summary["design_s"] = time.perf_counter() - start
            tr = simulate_profile(params, target, prof, evaluate_cfg)
            res = _score(np.asarray(tr.time), np.asarray(tr.length), np.asarray(tr.pressure), prof.demand,
                         prof.knots, target, lim, int(tr.status))
        elif method == "feedback":
            pid = LengthPID(jnp.asarray(DEFAULT_LOG_GAINS), jnp.asarray(prof.knots), jnp.asarray(prof.demand))
            draws = parameter_draws(n_draws, seed, robust, params) if robust else None
            cost = pid_cost_fn(params, target, t1, pid, draws, lim)
            tuned = tune_pid(cost, pid.log_gains, iterations)
            summary["tuning_s"] = tuned.wall_s
            summary["gains"] = tuned.gains
            summary["tuning_cost_history"] = tuned.cost_history
            summary["robust_draws"] = None if not robust else {"source": robust, "n": n_draws, "seed": seed}
            pid = eqx.tree_at(lambda c: c.log_gains, pid, jnp.asarray(tuned.log_gains))
            summary["design_s"] = time.perf_counter() - start
            res = run_closed_loop(Plant.make(params, evaluate_cfg), pid, target, t1, lim)
        else:
            mpc = MPC()
            summary["design_s"] = time.perf_counter() - start
            res = run_closed_loop(Plant.make(params, evaluate_cfg), mpc, target, t1, lim)
            summary["mpc_step_s_median"] = float(np.median(res.step_s[1:]))
            summary["mpc_step_s_p95"] = float(np.percentile(res.step_s[1:], 95))
            summary["mpc"] = {"dt_s": mpc.dt, "horizon": mpc.horizon, "w_move": mpc.w_move}
    summary["evaluation_s"] = time.perf_counter() - start - summary["design_s"]
    summary["tracking_rmse_m"] = res.rmse_m
    summary["pressure_limit_crossed"] = res.pressure_limit_crossed
    summary["peak_pressure_Pa"] = float(np.nanmax(res.pressure))
    summary["status"] = gj.status_name(res.status) if res.status != 1 else "pressure_limit"
    if figure is not None:
        summary["figure"] = str(control_figure(res, target, figure, lim,
                                               f"{drive} drive, {method}: RMSE {1e3 * res.rmse_m:.2f} mm ({evaluate_on})",
                                               drive))
    return summary


def tune_stepper(params, target: Target, t1: float, microsteps: int = 1, rates=(20.0, 25.0, 50.0),
                 leads=(0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4), gates=(160e3, 200e3, 240e3, float("inf"))):
    """The step controller's rate (Hz), lead (s) and pressure gate (Pa) by search on the fast model (its cost is
    piecewise constant in them, so a grid, not a gradient; leads 50 ms apart).
    → (best :class:`StepController`, its RMSE m)."""
    plant = Plant.make(params, gj.Config(drive="inverse", t1=t1), microstep=microsteps > 1)
    lim = limits(params)
    best = None
    for rate in rates:
        for lead in leads:
            for gate in gates:
                ctrl = StepController(rate=rate, lead=lead, microsteps=microsteps, pressure_gate=gate)
                res = run_closed_loop(plant, ctrl, target, t1, lim)
                admissible = np.isfinite(res.rmse_m) and not res.pressure_limit_crossed
                if admissible and (best is None or res.rmse_m < best[1]):
                    best = (ctrl, res.rmse_m)
    return best


def control_figure(res: ClosedLoopResult, target: Target, path, lim: Limits, title: str, drive: str):
    """Command, pressure and length against the target (three panels)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    if drive == "forward":
        ax[0].plot(res.tick_time, np.asarray(res.command) / 1e3, drawstyle="steps-post")
        ax[0].set_ylabel("demand (kPa)")
    else:
        ax[0].step(res.tick_time, res.command, where="post")
        ax[0].set_ylabel("step count")
    ax[1].plot(res.time, res.pressure / 1e3)
    ax[1].axhline(lim.pressure_limit / 1e3, color="r", ls="--", label="membrane limit")
    ax[1].set_ylabel("pressure (kPa)")
    ax[1].legend(loc="upper left")
    ax[2].plot(target.time, 1e3 * target.length, "k", lw=1, label="target")
    ax[2].plot(res.time, 1e3 * res.length, label="robot")
    ax[2].set_ylabel("length (mm)")
    ax[2].set_xlabel("time (s)")
    ax[2].set_xlim(0, res.time[-1])
    ax[2].legend(loc="upper left")
    ax[0].set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


__all__ = [
    "MPC", "ClosedLoopResult", "LengthPID", "Limits", "Plant", "ProfileResult", "StepController", "Target",
    "TuneResult", "add_arguments", "command", "design", "limits", "linearize", "operating_point",
    "optimize_profile", "optimize_steps", "parameter_draws", "pid_cost_fn", "plan_steps", "plant_params",
    "ramp_with_pauses", "rmse", "run_closed_loop", "simulate_profile", "simulate_steps", "step_commands", "step_length",
    "step_sequence", "target_from_experiment", "tune_pid", "tune_stepper", "with_microstepping",
]
