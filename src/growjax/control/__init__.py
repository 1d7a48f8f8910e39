"""Control design on the differentiable model: linearisation, trajectory optimisation, length feedback, MPC.

What is here, in the order a design uses it:

* `linearize` — the state-space model (A, B, C, D) of pressure demand → length (forward drive) or
  step command → length (stepper) about an operating point, from exact JAX Jacobians of the fast
  configuration's vector field, as a python-control ``StateSpace`` (``sys.A`` … work with ``scipy.signal``).
* `optimize_profile` — the pressure-demand profile (piecewise linear on fixed knots) that makes the
  robot follow a desired length, by least squares with forward-mode Jacobians through
  `growjax.simulation.simulate` (all knots in one merged sensitivity solve), inside the demand box [0, the
  pressure ceiling]. For the stepper drive (integer commands) an open-loop step schedule is found on the model
  without gradients: `optimize_steps` searches the lead of a schedule read off the target, `plan_steps` replays
  the steps the tuned closed-loop step controller issues on the model.
* `run_closed_loop` — a sampled-data length controller around either configuration of the plant:
  `LengthPID` (forward drive, outer loop over the pressure PID, with the optimised profile as
  feed-forward), `StepController` (stepper: back-and-forth steps on the length error) and
  `MPC` (forward drive; nonlinear least squares on the fast model from the current state).
* `run_on_estimate` — output feedback: the length PID on an estimate of the length from the pump's sensors
  alone (any `LengthEstimator`; `growjax.track.Filter` is one).
* `tune_pid` — gains by gradient descent on the closed-loop tracking cost, optionally averaged over
  parameter draws (robust design: a posterior's, `parameter_draws`, and the rig's within its
  tolerances, `growjax.calibration.tolerance.rig_draws`).
* `design_controller` — one design (drive × method) end to end, summarised for JSON (the ``growjax control``
  command).

Every design respects the rig's limits (`growjax.model.limits`): the demand under the pressure ceiling, a run
that crosses the membrane limit flagged, the stepper's tick rate under its step rate.

The plant of a closed loop (`Plant`) is stepped tick by tick from its state through
`growjax.simulation.simulate.simulate_from`, with the solver and settings of its configuration, so a controller
designed on the fast model is evaluated on the model it was not designed on. All quantities SI: lengths m,
pressures Pa, times s. Its figure: `growjax.plotting.control_figure`.
"""

from growjax.control.controllers import (
    MPC,
    ClosedLoopResult,
    LengthPID,
    StepController,
    pid_loop,
    run_closed_loop,
    score,
)
from growjax.control.estimated import PUMP_NOISE, EstimatedLoop, LengthEstimator, run_on_estimate
from growjax.control.linearise import linearize, operating_point
from growjax.control.plant import (
    Plant,
    catheter_signal,
    segment_inputs,
    with_microstepping,
)
from growjax.control.profile import (
    ProfileResult,
    optimize_profile,
    optimize_steps,
    simulate_profile,
    simulate_steps,
    step_commands,
)
from growjax.control.targets import (
    Target,
    plant_params,
    ramp_with_pauses,
    rmse,
    step_length,
    step_sequence,
    target_from_experiment,
)
from growjax.control.tuning import (
    DEFAULT_LOG_GAINS,
    TuneResult,
    parameter_draws,
    pid_cost_fn,
    plan_steps,
    tune_pid,
    tune_stepper,
)
from growjax.control.workflow import design_controller

__all__ = [
    "DEFAULT_LOG_GAINS",
    "MPC",
    "PUMP_NOISE",
    "ClosedLoopResult",
    "EstimatedLoop",
    "LengthEstimator",
    "LengthPID",
    "Plant",
    "ProfileResult",
    "StepController",
    "Target",
    "TuneResult",
    "catheter_signal",
    "design_controller",
    "linearize",
    "operating_point",
    "optimize_profile",
    "optimize_steps",
    "parameter_draws",
    "pid_cost_fn",
    "pid_loop",
    "plan_steps",
    "run_on_estimate",
    "plant_params",
    "ramp_with_pauses",
    "rmse",
    "run_closed_loop",
    "score",
    "segment_inputs",
    "simulate_profile",
    "simulate_steps",
    "step_commands",
    "step_length",
    "step_sequence",
    "target_from_experiment",
    "tune_pid",
    "tune_stepper",
    "with_microstepping",
]
