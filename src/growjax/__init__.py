"""growjax: a differentiable JAX simulator of the MAMMOBOT hydraulic soft growing robot."""

import jax

jax.config.update("jax_enable_x64", True)

from growjax.model import (  # noqa: E402
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
from growjax.params import Parameters, as_dict, get, parameter_names, reference, replace, validate  # noqa: E402
from growjax.robot import pressure_limit  # noqa: E402
from growjax.signals import Constant, Inputs, PulseTrain, Sampled, StepSchedule, published_pulse  # noqa: E402

__all__ = [
    "OK", "PRESSURE_LIMIT", "SOLVER_FAILED", "Config", "Network", "Trajectory", "network", "simulate",
    "status_name", "Parameters", "as_dict", "get", "parameter_names", "reference", "replace", "validate",
    "pressure_limit", "Constant", "Inputs", "PulseTrain", "Sampled", "StepSchedule", "published_pulse",
]
__version__ = "0.1.0"
