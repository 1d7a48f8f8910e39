"""growjax: a differentiable JAX simulator of the MAMMOBOT hydraulic soft growing robot.

Importing growjax turns on float64 in JAX for the process (``jax_enable_x64``): the model
spans pressures of 1e5 Pa and compliances of 1e-13 m³/Pa, which float32 cannot resolve.
`growjax.simulation.xla_flags` holds an opt-in XLA:CPU option that compiles the solver's loop into one kernel.
"""

__version__ = "0.9.0"  # the one version string: pyproject.toml reads it (setuptools dynamic version)

import jax

jax.config.update("jax_enable_x64", True)  # the package's one global setting; see the module docstring

from growjax.model import effects
from growjax.model.effects import Effect
from growjax.model.limits import Limits, limits
from growjax.model.params import (
    Parameters,
    as_dict,
    get,
    parameter_names,
    reference,
    replace,
    validate,
    with_effects,
)
from growjax.model.robot import pressure_limit
from growjax.model.signals import (
    Constant,
    Inputs,
    KnotProfile,
    PulseTrain,
    Sampled,
    StepSchedule,
    published_pulse,
)
from growjax.simulation.config import Config
from growjax.simulation.simulate import input_breaks, simulate, simulate_members
from growjax.simulation.trajectory import (
    OK,
    PRESSURE_LIMIT,
    SOLVER_FAILED,
    Trajectory,
    status_name,
)

__all__ = [
    "OK",
    "PRESSURE_LIMIT",
    "SOLVER_FAILED",
    "Config",
    "Constant",
    "Effect",
    "Inputs",
    "KnotProfile",
    "Limits",
    "Parameters",
    "PulseTrain",
    "Sampled",
    "StepSchedule",
    "Trajectory",
    "as_dict",
    "effects",
    "get",
    "input_breaks",
    "limits",
    "parameter_names",
    "pressure_limit",
    "published_pulse",
    "reference",
    "replace",
    "simulate",
    "simulate_members",
    "status_name",
    "validate",
    "with_effects",
]
