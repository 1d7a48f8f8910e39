"""The limits an input must respect on the rig: the membrane's safe pressure and the ceiling kept below it, the
robot's and the syringes' strokes, the pump platform's speed and the stepper's step rate.

One set of limits serves every workflow: the control design keeps its demand under ``pressure_ceiling`` and
flags a run whose sensed pressure crosses ``membrane_limit``; the experiment design checks the sensed pressure,
the length and the syringes' travel of every draw of the rig against the ceilings. SI units: Pa, m, m/s, steps/s.
"""

from __future__ import annotations

import equinox as eqx

from growjax.model.params import Parameters
from growjax.model.robot import pressure_limit

__all__ = ["MAX_STEP_RATE", "PRESSURE_MARGIN", "STROKE_MARGIN", "Limits", "limits"]

PRESSURE_MARGIN = 0.9  # the ceiling of the sensed pressure and of the demand, as a share of the membrane limit
STROKE_MARGIN = 0.95  # the ceiling of the robot's length, as a share of its stroke
MAX_STEP_RATE = 100.0  # steps/s the stepper drive can make


class Limits(eqx.Module):
    """The limits of one rig. Build them from its parameters with `limits`.

    Attributes:
        membrane_limit: Pa, the membrane's safe pressure (paper eq. 8, `growjax.model.robot.pressure_limit`).
        pressure_ceiling: Pa, the ceiling of the sensed pressure and of the pressure demand (a margin below
            ``membrane_limit``).
        length_ceiling: m, the ceiling of the robot's length (a margin below its stroke).
        syringe_stroke: m, the syringes' travel.
        max_pump_speed: m/s, the pump platform's speed limit; None: not checked (the forward drive's pump is an
            ideal torque source in the model, so the model sets no limit to its speed).
        max_step_rate: steps/s, the stepper drive's step rate.
    """

    membrane_limit: float
    pressure_ceiling: float
    length_ceiling: float
    syringe_stroke: float
    max_pump_speed: float | None = None
    max_step_rate: float = MAX_STEP_RATE

    def summary(self) -> dict:
        """The pressure, length, travel and speed limits for JSON, units in the keys."""
        return {
            "pressure_ceiling_Pa": self.pressure_ceiling,
            "membrane_limit_Pa": self.membrane_limit,
            "length_ceiling_m": self.length_ceiling,
            "syringe_stroke_m": self.syringe_stroke,
            "max_pump_speed_m_s": self.max_pump_speed,
        }


def limits(
    params: Parameters,
    *,
    margin: float = PRESSURE_MARGIN,
    stroke_margin: float = STROKE_MARGIN,
    max_pump_speed: float | None = None,
    max_step_rate: float = MAX_STEP_RATE,
) -> Limits:
    """The `Limits` of the rig ``params`` describes.

    Args:
        params: the rig's parameters (its robot's membrane and stroke, its pump's syringes).
        margin: the pressure ceiling as a share of the membrane limit, in (0, 1].
        stroke_margin: the length ceiling as a share of the robot's stroke, in (0, 1].
        max_pump_speed: m/s, the pump platform's speed limit (None: not checked).
        max_step_rate: steps/s, the stepper drive's step rate.

    Returns:
        The limits: membrane limit, ``margin`` × it, ``stroke_margin`` × the stroke, the syringes' stroke, and the
        two rates as given.

    Raises:
        ValueError: a margin outside (0, 1], or a speed or step rate that is not positive.
    """
    for name, share in (("margin", margin), ("stroke_margin", stroke_margin)):
        if not 0.0 < share <= 1.0:
            raise ValueError(f"{name} must lie in (0, 1], got {share}")
    if max_pump_speed is not None and not max_pump_speed > 0.0:
        raise ValueError(f"max_pump_speed must be a positive speed (m/s), got {max_pump_speed}")
    if not max_step_rate > 0.0:
        raise ValueError(f"max_step_rate must be a positive rate (steps/s), got {max_step_rate}")
    membrane = float(pressure_limit(params.robot))
    return Limits(
        membrane_limit=membrane,
        pressure_ceiling=margin * membrane,
        length_ceiling=stroke_margin * float(params.robot.stroke),
        syringe_stroke=float(params.pump.syringe_stroke),
        max_pump_speed=max_pump_speed,
        max_step_rate=max_step_rate,
    )
