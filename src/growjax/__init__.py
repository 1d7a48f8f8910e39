"""growjax: a differentiable JAX simulator of the MAMMOBOT hydraulic soft growing robot."""

import jax

jax.config.update("jax_enable_x64", True)

from growjax.model import (
    OK,
    PRESSURE_LIMIT,
    SOLVER_FAILED,
    Config,
    Network,
    Trajectory,
    network,
    simulate,
    status_name,
)
from growjax.params import (
    Parameters,
    as_dict,
    get,
    parameter_names,
    reference,
    replace,
    validate,
)
from growjax.quasistatic import QuasiStaticConfig
from growjax.robot import pressure_limit
from growjax.signals import (
    Constant,
    Inputs,
    PulseTrain,
    Sampled,
    StepSchedule,
    published_pulse,
)

__all__ = [
    "OK",
    "PRESSURE_LIMIT",
    "SOLVER_FAILED",
    "Config",
    "Constant",
    "Inputs",
    "Network",
    "Parameters",
    "PulseTrain",
    "QuasiStaticConfig",
    "Sampled",
    "StepSchedule",
    "Trajectory",
    "as_dict",
    "get",
    "network",
    "parameter_names",
    "pressure_limit",
    "published_pulse",
    "reference",
    "replace",
    "simulate",
    "status_name",
    "validate",
]
__version__ = "0.1.0"
