"""The model: the rig's components (fluid, hoses and tank, pump, motor, robot), its parameters and limits, the
catalogue of effects beyond the published model, and the input signals.

The components are modules of their own (`growjax.model.fluid`, `growjax.model.hydraulics`,
`growjax.model.pump`, `growjax.model.motor`, `growjax.model.robot`, `growjax.model.smooth`); this package
re-exports what a user of the model handles: the parameters, the limits, the effects and the signals.
"""

from growjax.model import effects
from growjax.model.effects import CATALOGUE, Effect, register
from growjax.model.limits import Limits, limits
from growjax.model.params import (
    ALIASES,
    DRIVES,
    Parameters,
    admissible_rows,
    as_dict,
    get,
    parameter_names,
    physical_ranges,
    reference,
    replace,
    resolve_name,
    validate,
    with_effects,
)
from growjax.model.robot import GROWTH_LAWS, pressure_limit
from growjax.model.signals import (
    Constant,
    Inputs,
    KnotProfile,
    PulseTrain,
    Sampled,
    StepSchedule,
    published_pulse,
)

__all__ = [
    "ALIASES",
    "CATALOGUE",
    "DRIVES",
    "GROWTH_LAWS",
    "Constant",
    "Effect",
    "Inputs",
    "KnotProfile",
    "Limits",
    "Parameters",
    "PulseTrain",
    "Sampled",
    "StepSchedule",
    "admissible_rows",
    "as_dict",
    "effects",
    "get",
    "limits",
    "parameter_names",
    "physical_ranges",
    "pressure_limit",
    "published_pulse",
    "reference",
    "register",
    "replace",
    "resolve_name",
    "validate",
    "with_effects",
]
