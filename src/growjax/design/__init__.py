"""Design of the next experiment: the forward drive's pressure demand, or the stepper's step schedule, that makes
the next fit most precise about the parameters of interest, safe on every plausible rig.

What is here, in the order a design uses it:

* `Knowledge` (`from_fit`, `from_summary`) — what is known: the parameters of interest at their
  estimate, their covariance of ln θ, the rig's tolerances and the residual model (`.knowledge`).
* `DesignSpace` — the demand as a piecewise-linear profile on fixed knots in (0, p_max), a smooth map
  of unconstrained design variables; the catheter as in the experiment already run; the CSV in the rig's
  terms. `StepperSpace` (`stepper_space`) — the stepper drive's schedule: −1, 0 or +1 step at each
  of its position controller's edges, written as the desired length the controller turns back into it
  (`.space`).
* `solve` — the length and pressure with their sensitivities to (ln θ, the rig's errors), one forward
  sensitivity solve that forward mode differentiates again (`.sensitivity`).
* `posterior`, `Criterion` (`AOptimal`, `DOptimal`) — the expected posterior covariance under the discrepancy,
  the noise and the rig as nuisance, linearised, and the criterion a design minimises on it (`.criterion`).
* `draws`, `check`, `penalty` — the rig's limits (`growjax.model.limits`: the membrane limit with its margin, the
  strokes) checked over draws of the rig and θ (`.constraints`).
* `make` (a `DesignProblem`), `evaluate`, `smoothed_gradient`, `value_and_gradient` — the problem, its
  objective, the slope the descent follows (differences over a step of the demand) and the exact derivative by
  forward mode through the model (`.problem`).
* `Discrimination`, `discrimination.make`, `discrimination.statistic` — the criterion of model
  discrimination between two rival effects: min(T_AB, T_BA), the linearised expected 2ΔlogL by which the data
  reject the wrong one (`.discrimination`).
* `random_admissible`, `multistart`, `local_search` — the random baseline, the descent, and
  the stepper's search over its schedule's choices (`.optimise`).
* `design` — all of it end to end (`.workflow`; the ``growjax design`` command), `discriminate`
  its sibling for two rival effects (``growjax design --discriminate A,B``), and `design_figure`.

SI units throughout: s, Pa, m; uncertainties of ln θ (relative).
"""

from growjax.design import discrimination
from growjax.design.constraints import Check, check, draws, penalty, stack
from growjax.design.criterion import AOptimal, Criterion, DOptimal, Prediction, information, posterior
from growjax.design.discrimination import Discrimination
from growjax.design.figure import design_figure
from growjax.design.knowledge import Knowledge, from_fit, from_summary
from growjax.design.optimise import Descent, RandomBatch, adam, local_search, multistart, neighbours, random_admissible
from growjax.design.problem import (
    DesignProblem,
    covariances,
    evaluate,
    evaluate_many,
    make,
    smoothed_gradient,
    value_and_gradient,
    values,
)
from growjax.design.sensitivity import Sensitivities, solve
from growjax.design.space import DesignSpace, StepperSpace, catheter_of, check_p_max, demand_space, stepper_space
from growjax.design.workflow import DesignError, DesignResult, design, discriminate, published_inputs

__all__ = [
    "AOptimal",
    "Check",
    "Criterion",
    "DOptimal",
    "Descent",
    "DesignError",
    "DesignProblem",
    "DesignResult",
    "DesignSpace",
    "Discrimination",
    "Knowledge",
    "Prediction",
    "RandomBatch",
    "Sensitivities",
    "StepperSpace",
    "adam",
    "catheter_of",
    "check",
    "check_p_max",
    "covariances",
    "demand_space",
    "design",
    "design_figure",
    "discriminate",
    "discrimination",
    "draws",
    "evaluate",
    "evaluate_many",
    "from_fit",
    "from_summary",
    "information",
    "local_search",
    "make",
    "multistart",
    "neighbours",
    "penalty",
    "posterior",
    "published_inputs",
    "random_admissible",
    "smoothed_gradient",
    "solve",
    "stack",
    "stepper_space",
    "value_and_gradient",
    "values",
]
