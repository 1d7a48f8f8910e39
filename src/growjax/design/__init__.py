"""Design of the next experiment: the forward drive's pressure demand, or the stepper's step schedule, that makes
the next fit most precise about the parameters of interest, safe on every plausible rig.

What is here, in the order a design uses it:

* :class:`Knowledge` (:func:`from_fit`, :func:`from_summary`) — what is known: the parameters of interest at their
  estimate, their covariance of ln θ, the rig's tolerances and the residual model (:mod:`.knowledge`).
* :class:`DesignSpace` — the demand as a piecewise-linear profile on fixed knots in (0, p_max), a smooth map
  of unconstrained design variables; the catheter as in the experiment already run; the CSV in the rig's
  terms. :class:`StepperSpace` (:func:`stepper_space`) — the stepper drive's schedule: −1, 0 or +1 step at each
  of its position controller's edges, written as the desired length the controller turns back into it
  (:mod:`.space`).
* :func:`solve` — the length and pressure with their sensitivities to (ln θ, the rig's errors), one forward
  sensitivity solve that forward mode differentiates again (:mod:`.sensitivity`).
* :class:`Precision`, :func:`posterior` — the expected posterior covariance under the discrepancy, the noise and
  the rig as nuisance, linearised, and its A- or D-criterion (:mod:`.criterion`).
* :func:`limits`, :func:`draws`, :func:`check`, :func:`penalty` — the membrane limit with the control module's
  margin, the stroke, checked over draws of the rig and θ (:mod:`.constraints`).
* :func:`make`, :func:`evaluate`, :func:`smoothed_gradient`, :func:`value_and_gradient` — the problem, its
  objective, the slope the descent follows (differences over a step of the demand) and the exact derivative by
  forward mode through the model (:mod:`.problem`).
* :class:`Discrimination`, :func:`discrimination.make`, :func:`discrimination.statistic` — the criterion of model
  discrimination between two rival effects: min(T_AB, T_BA), the linearised expected 2ΔlogL by which the data
  reject the wrong one (:mod:`.discrimination`).
* :func:`random_admissible`, :func:`multistart`, :func:`local_search` — the random baseline, the descent, and
  the stepper's search over its schedule's choices (:mod:`.optimise`).
* :func:`design` — all of it end to end (:mod:`.workflow`; the ``growjax design`` command), :func:`discriminate`
  its sibling for two rival effects (``growjax design --discriminate A B``), and :func:`design_figure`.

SI units throughout: s, Pa, m; uncertainties of ln θ (relative).
"""

from growjax.design import discrimination
from growjax.design.constraints import Check, Limits, check, draws, limits, penalty, stack
from growjax.design.criterion import Precision, Prediction, information, posterior
from growjax.design.discrimination import Discrimination
from growjax.design.figure import design_figure
from growjax.design.knowledge import Knowledge, from_fit, from_summary
from growjax.design.optimise import Descent, RandomBatch, adam, local_search, multistart, neighbours, random_admissible
from growjax.design.problem import (
    Problem,
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
    "Check",
    "Descent",
    "DesignError",
    "DesignResult",
    "DesignSpace",
    "Discrimination",
    "Knowledge",
    "Limits",
    "Precision",
    "Prediction",
    "Problem",
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
    "limits",
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
