"""The calibrated model as a discrete-time state-space system: the fast configuration's state advanced over one
sample interval with that interval's inputs, and the rig's sensors read from the state.

The state x (N,) is, in order: the fast configuration's scaled state (n, its layout: ``growjax.simulation.fast``),
the parameters carried in the state (k, `growjax.track.noise.StateParameter`), the estimated inputs' levels
(j, `growjax.track.noise.InputState`) and the length discrepancy (δ, δ') (0 or 2). Over a sample interval
[t_a, t_b] the model's part is integrated by the configuration's own solver from its state
(`growjax.simulation.simulate.simulate_from`, the L-stable Rosenbrock method with error control), with the
parameters and inputs the state holds; the parameters and input levels carry over (their random walks are
process noise) and the discrepancy follows its exact linear transition. Everything is a pure JAX function of x:
``jax.jacfwd`` gives the transition's Jacobian through the solver's forward-mode tangents.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

import growjax.track.noise as tn
from growjax.model import effects as fx
from growjax.model import params as gp
from growjax.model.signals import Constant, Inputs
from growjax.simulation import fast as fm
from growjax.simulation.config import Config
from growjax.simulation.simulate import input_breaks, simulate_from
from growjax.track.sensors import Sensor

WINDOW_STEPS = 200  # step budget of one sample interval (a pulse edge inside one takes about a dozen)
SWITCH_WIDTH = 300.0  # Pa: the narrowest band over which the filter's model opens the valves' bypass
OUTPUTS = ("length", "pressure", "syringe_displacement", "robot_flow", "catheter_length")
OUTPUT_COLUMNS = {
    "length": "robot_length_m",
    "pressure": "pressure_Pa",
    "syringe_displacement": "syringe_displacement_m",
    "robot_flow": "robot_flow_m3_s",
    "catheter_length": "catheter_length_m",
}


def window_config(config: Config, sample_interval: float) -> Config:
    """``config`` as a filter steps it: the fast fidelity, each interval opening with a step of the sample
    interval (s), a small step budget, the pressure limit flagged rather than stopping a run, and the valves'
    bypass opening over at least `SWITCH_WIDTH` Pa.

    The bypass carries the robot's retraction. Opened over a band of a few pascals, the retraction chatters
    (the chamber's pressure swings about the robot's across the band every millisecond) and the transition's
    derivative over one sample interval there reaches 1e34: the extended filter's covariance overflows. Opened
    over 300 Pa, below the pressure sensor's noise, the derivative stays below 2e5 (about 1e4 elsewhere on the
    pulse). A wider band smooths more but moves the retraction away from the rig's: over a minute of growth
    the estimated Y drifts outside its band more often (``benchmarks/track.py``).

    Raises:
        ValueError: the reference fidelity (too slow to step live; the filter's data may come from it).
    """
    if config.fidelity != "fast":
        raise ValueError("the filter steps the fast configuration (the reference is for making test data)")
    if not (np.isfinite(sample_interval) and sample_interval > 0):
        raise ValueError(f"the sample interval must be a positive time (s), got {sample_interval}")
    return config.replace(
        first_step=float(sample_interval),
        max_steps=config.max_steps or WINDOW_STEPS,
        stop_at_pressure_limit=False,
        switch_width=max(config.switch_width, SWITCH_WIDTH),
    ).resolved()


class StateSpace(eqx.Module):
    """The fast configuration of ``params`` as a state-space system for a filter.

    Attributes:
        params: the nominal parameters (effects included); the state's parameters are relative to them.
        config: the fast configuration a sample interval is integrated with (`window_config`).
        sensors: the rig's sensors read at every sample (`growjax.track.sensors`), in their order.
        parameters: parameters in the state (the estimated ones, then the rig's toleranced ones).
        inputs: estimated inputs (their levels in the state).
        discrepancy: the length discrepancy, or None.
    """

    params: gp.Parameters
    config: Config = eqx.field(static=True)
    sensors: tuple[Sensor, ...] = eqx.field(static=True)
    parameters: tuple[tn.StateParameter, ...] = eqx.field(static=True, default=())
    inputs: tuple[tn.InputState, ...] = eqx.field(static=True, default=())
    discrepancy: tn.Discrepancy | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        names = [p.name for p in self.parameters]
        if len(set(names)) != len(names):
            raise ValueError(f"a parameter is carried in the state twice: {names}")
        fields = [i.field for i in self.inputs]
        if len(set(fields)) != len(fields):
            raise ValueError(f"an input is estimated twice: {fields}")
        for i in self.inputs:
            if i.drive is not None and i.drive != self.config.drive:
                raise ValueError(f"the {i.field} is an input of the {i.drive} drive, not of the {self.config.drive}")
        if any(s.output == "catheter_length" for s in self.sensors) and "catheter_length" not in fields:
            raise ValueError("a catheter sensor reads the catheter's insertion: estimate it as an input too")

    # -- the layout ---------------------------------------------------------------------------------------------

    @property
    def model_size(self) -> int:
        """n: the fast configuration's states."""
        return len(fm.layout(self.params, self.config.drive)[0])

    @property
    def sizes(self) -> tuple[int, int, int, int]:
        """(n model states, k parameters, j inputs, 0 or 2 discrepancy states)."""
        return self.model_size, len(self.parameters), len(self.inputs), 0 if self.discrepancy is None else 2

    @property
    def size(self) -> int:
        """N: the state's length."""
        return sum(self.sizes)

    def state_names(self) -> tuple[str, ...]:
        """A name for every element of the state."""
        names = fm.layout(self.params, self.config.drive)[0]
        coords = tuple(f"ln {p.name}" if p.log else p.name for p in self.parameters)
        levels = tuple(i.field for i in self.inputs)
        return names + coords + levels + (("discrepancy", "discrepancy_rate") if self.discrepancy else ())

    def split(self, x: Float[Array, " N"]) -> tuple[Array, Array, Array, Array]:
        """(model state (n,), parameters' coordinates (k,), input levels (j,), discrepancy (0 or 2,)) of ``x``."""
        n, k, j, _ = self.sizes
        return x[:n], x[n : n + k], x[n + k : n + k + j], x[n + k + j :]

    def scales(self) -> Float[Array, " n"]:
        """SI units per unit of each model state."""
        return jnp.asarray(fm.layout(self.params, self.config.drive)[1])

    # -- the model at a state -----------------------------------------------------------------------------------

    def parameters_at(self, coordinates: Float[Array, " k"]) -> gp.Parameters:
        """The parameters with those carried in the state at ``coordinates``."""
        values = {p.name: p.value(gp.get(self.params, p.name), coordinates[i]) for i, p in enumerate(self.parameters)}
        return gp.replace(self.params, **values) if values else self.params

    def inputs_at(self, levels: Float[Array, " j"], inputs: Inputs) -> Inputs:
        """``inputs`` with each estimated one held at its level (SI: state × scale)."""
        held = {i.field: Constant(levels[m] * i.scale) for m, i in enumerate(self.inputs)}
        return dataclasses.replace(inputs, **held) if held else inputs

    def breaks(self, inputs: Inputs, t0: float, t1: float):
        """(jump times, slope-break times) of the inputs the model sees over [t0, t1] s, padded (the estimated
        ones held constant): what every interval's solve steps onto. Needs concrete inputs."""
        zero = jnp.zeros(len(self.inputs))
        return input_breaks(self.inputs_at(zero, inputs), self.config.replace(t0=float(t0), t1=float(t1)))

    def outputs(self, x: Float[Array, " N"], t, inputs: Inputs) -> dict:
        """What the sensors and the bands read at state ``x`` and time ``t`` (s): {output: value} SI, the length
        with the discrepancy added (`OUTPUTS`)."""
        y, w, u, d = self.split(x)
        params = fx.apply_all(self.parameters_at(w))
        held = self.inputs_at(u, inputs)
        prep = fm.prepare(params, self.config)
        length, pressure, flow, x_p, _ = fm.rates(t, y * self.scales(), params, held, self.config, prep)[1]
        if self.discrepancy is not None:
            length = length + d[0] * tn.DISCREPANCY_SCALE
        catheter = jnp.asarray(held.catheter_length(t), float)
        return dict(zip(OUTPUTS, (length, pressure, x_p, flow, catheter)))

    def measure(self, x: Float[Array, " N"], t, inputs: Inputs) -> Float[Array, " m"]:
        """The sensors' noise-free readings (m,) at state ``x``, SI."""
        out = self.outputs(x, t, inputs)
        return jnp.stack([out[s.output] for s in self.sensors])

    def noise_sd(self) -> Float[Array, " m"]:
        """The sensors' noise standard deviations (m,), SI."""
        return jnp.asarray([s.noise for s in self.sensors], float)

    # -- the transition -----------------------------------------------------------------------------------------

    def advance_model(self, x: Float[Array, " N"], inputs: Inputs, ta, tb, breaks) -> tuple[Array, Array]:
        """(the model's scaled state (n,) at ``tb``, solver status: 0 ok, 2 failed) from ``x`` at ``ta`` (s), over
        the inputs ``inputs`` with their ``breaks`` (`breaks`)."""
        y, w, u, _ = self.split(x)
        tb_arr = jnp.asarray(tb, float)
        traj = simulate_from(
            self.parameters_at(w), self.inputs_at(u, inputs), self.config, y, (ta, tb), tb_arr[None], breaks
        )
        return traj.final_state, traj.status

    def advance(self, x: Float[Array, " N"], inputs: Inputs, ta, tb, breaks) -> tuple[Array, Array]:
        """(the state's mean transition to ``tb``: x (N,), solver status) from ``x`` at ``ta`` (s)."""
        y1, status = self.advance_model(x, inputs, ta, tb, breaks)
        _, w, u, d = self.split(x)
        if self.discrepancy is not None:
            d = self.discrepancy.transition(tb - ta)[0] @ d
        return jnp.concatenate([y1, w, u, d]), status

    def linearised_advance(self, x: Float[Array, " N"], inputs: Inputs, ta, tb, breaks):
        """(x at ``tb`` (N,), its Jacobian ∂x(tb)/∂x(ta) (N, N), solver status): the model's part through the
        solver's forward-mode tangents in its state, parameters and input levels; the rest exactly (linear)."""
        n, k, j, m = self.sizes
        head = n + k + j

        def model_part(z):
            y1, status = self.advance_model(jnp.concatenate([z, x[head:]]), inputs, ta, tb, breaks)
            return y1, status

        (y1, status), jac = _value_and_jacfwd(model_part, x[:head])
        big = jnp.zeros((self.size, self.size)).at[:n, :head].set(jac).at[n:head, n:head].set(jnp.eye(k + j))
        d = x[head:]
        if m:
            a = self.discrepancy.transition(tb - ta)[0]
            big = big.at[head:, head:].set(a)
            d = a @ d
        return jnp.concatenate([y1, x[n:head], d]), big, status

    def process_noise(self, dt) -> Float[Array, "N N"]:
        """Q (N, N): the covariance the interval of ``dt`` s adds (the walks and the discrepancy)."""
        n, k, j, m = self.sizes
        diag = jnp.concatenate([jnp.zeros(n), tn.parameter_noise(self.parameters, dt), tn.input_noise(self.inputs, dt)])
        q = jnp.diag(jnp.concatenate([diag, jnp.zeros(m)]))
        if m:
            q = q.at[-m:, -m:].set(self.discrepancy.transition(dt)[1])
        return q

    # -- the start ----------------------------------------------------------------------------------------------

    def initial(self) -> tuple[Float[Array, " N"], Float[Array, "N N"]]:
        """(mean (N,), covariance (N, N)) of the state at rest: the model's state at the parameters' nominal
        values, its covariance that of the parameters' priors carried through the rest state's dependence on them."""
        n, k, j, m = self.sizes

        def rest(w):
            return fm.initial_state(fx.apply_all(self.parameters_at(w)), self.config)

        (y0, _), dy = _value_and_jacfwd(lambda w: (rest(w), None), jnp.zeros(k))
        levels = jnp.asarray([i.prior_mean / i.scale for i in self.inputs], float)
        mean = jnp.concatenate([y0, jnp.zeros(k), levels, jnp.zeros(m)])
        p_w = jnp.diag(jnp.asarray(tn.parameter_prior(self.parameters)))
        p_u = jnp.diag(jnp.asarray([(i.prior_sd / i.scale) ** 2 for i in self.inputs], float))
        cov = jnp.zeros((self.size, self.size))
        cov = cov.at[:n, :n].set(dy @ p_w @ dy.T).at[:n, n : n + k].set(dy @ p_w).at[n : n + k, :n].set(p_w @ dy.T)
        cov = cov.at[n : n + k, n : n + k].set(p_w).at[n + k : n + k + j, n + k : n + k + j].set(p_u)
        if m:
            cov = cov.at[-m:, -m:].set(self.discrepancy.stationary())
        return mean, cov


def _value_and_jacfwd(fn, z):
    """((value, aux), ∂value/∂z) of ``fn(z) → (value, aux)`` in forward mode (the primal evaluated once)."""

    def with_value(v):
        value, aux = fn(v)
        return value, (value, aux)

    jac, out = jax.jacfwd(with_value, has_aux=True)(z)
    return out, jac


def state_space(
    params: gp.Parameters | None = None,
    *,
    drive: str = "forward",
    sensors: tuple[Sensor, ...] | None = None,
    estimate=(),
    prior_sd: dict | None = None,
    walk: dict | None = None,
    tolerances: dict | None = None,
    budget: bool = True,
    discrepancy: tn.Discrepancy | None = None,
    inputs=(),
    sample_interval: float = 0.01,
    config: Config | None = None,
) -> StateSpace:
    """The state-space model a filter runs, from what calibration found.

    Args:
        params: the nominal (calibrated) parameters; default ``growjax.reference(drive)``.
        drive: ``"forward"`` or ``"inverse"``.
        sensors: the rig's sensors (default pressure and syringe: `growjax.track.sensors.PUMP_SENSORS`).
        estimate: names of parameters to estimate (``Y``, ``fluid_leak.coefficient``, ...): random walks.
        prior_sd: {name: prior sd} of estimated parameters (relative; in their unit where nominally 0).
        walk: {name: random-walk sd per √s} of estimated parameters.
        tolerances: {rig parameter: relative sd} on top of the default budget (``budget``) or alone: static
            states (`growjax.calibration.tolerance`).
        budget: start from the default tolerance budget.
        discrepancy: the length discrepancy a fit found, or None.
        inputs: estimated inputs: `growjax.track.noise.InputState` or their field names.
        sample_interval: the readings' spacing, s (the solver's first step in each interval).
        config: the fast configuration (default ``growjax.Config(drive=drive)``).

    Raises:
        ValueError: an unknown name, a bad value, an input of the other drive.
    """
    from growjax.track.sensors import PUMP_SENSORS, sensor

    base = gp.reference(drive) if params is None else params
    config = Config(drive=drive) if config is None else config
    if config.drive != drive:
        raise ValueError(f"the configuration's drive ({config.drive}) is not the drive asked for ({drive})")
    chosen = tuple(sensor(c) for c in PUMP_SENSORS) if sensors is None else tuple(sensors)
    prior_sd = {gp.resolve_name(base, k): v for k, v in (prior_sd or {}).items()}
    walk = {gp.resolve_name(base, k): v for k, v in (walk or {}).items()}
    names = [gp.resolve_name(base, n) for n in estimate]
    stray = sorted((set(prior_sd) | set(walk)) - set(names))
    if stray:
        raise ValueError(f"a prior or walk is given for {stray[0]}, which is not estimated (--estimate)")
    chosen_params = tuple(
        tn.estimated_parameter(base, n, prior_sd=prior_sd.get(n), walk=walk.get(n)) for n in names
    ) + tn.rig_parameters(base, tolerances, default=budget, free=names)
    held = tuple(i if isinstance(i, tn.InputState) else tn.InputState(i) for i in inputs)
    return StateSpace(base, window_config(config, sample_interval), chosen, chosen_params, held, discrepancy)


__all__ = ["OUTPUTS", "OUTPUT_COLUMNS", "SWITCH_WIDTH", "WINDOW_STEPS", "StateSpace", "state_space", "window_config"]
