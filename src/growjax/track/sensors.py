"""What the rig measures of itself: each sensor, the model output it reads, its column and its noise.

A sensor reads one output of the model at a sample time (SI units): the sensed pressure before the check valve,
the syringe's displacement (the motor's encoder or the stepper's step count), the flow at the robot's inlet, the
catheter's insertion, the robot's length. Its noise is white and Gaussian with standard deviation ``noise`` (the
sensor's unit). A sample may be missing (NaN in its column): the filter then only predicts that sensor.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from growjax.data.experiment import Experiment


@dataclasses.dataclass(frozen=True)
class Sensor:
    """One sensor of the rig.

    Attributes:
        column: the experiment's column it reads (``pressure_Pa``, ...), also its name in outputs.
        output: the model output it measures: ``"pressure"``, ``"syringe_displacement"``, ``"robot_flow"``,
            ``"catheter_length"`` or ``"length"``.
        noise: standard deviation of its white noise, in the column's unit.
        short: the name the command line takes (``pressure``, ``syringe``, ...).
    """

    column: str
    output: str
    noise: float
    short: str

    def __post_init__(self):
        if not (np.isfinite(self.noise) and self.noise > 0):
            raise ValueError(f"the noise of sensor {self.column} must be a positive number, got {self.noise}")

    def with_noise(self, noise: float) -> Sensor:
        """This sensor with standard deviation ``noise`` (its unit)."""
        return dataclasses.replace(self, noise=float(noise))


# The sensors a rig may carry, with their default noise: the tank's pressure sensor (0.5 kPa), the syringe read to
# 5 µm, an inlet flow sensor (1e-9 m³/s, 2 % of the growth flow), the catheter's and the robot's length (0.2 mm).
SENSORS = {
    s.column: s
    for s in (
        Sensor("pressure_Pa", "pressure", 500.0, "pressure"),
        Sensor("syringe_displacement_m", "syringe_displacement", 5e-6, "syringe"),
        Sensor("robot_flow_m3_s", "robot_flow", 1e-9, "flow"),
        Sensor("catheter_length_m", "catheter_length", 2e-4, "catheter"),
        Sensor("robot_length_m", "length", 2e-4, "length"),
    )
}
SHORT_NAMES = {s.short: c for c, s in SENSORS.items()}
PUMP_SENSORS = ("pressure_Pa", "syringe_displacement_m")


def sensor(name: str, noise: float | None = None) -> Sensor:
    """The sensor named ``name`` (its column or its short name), with noise ``noise`` (None: its default).

    Raises:
        ValueError: an unknown name.
    """
    column = SHORT_NAMES.get(name, name)
    if column not in SENSORS:
        known = ", ".join(f"{s.short} ({c})" for c, s in SENSORS.items())
        raise ValueError(f"unknown sensor {name!r}; known: {known}")
    chosen = SENSORS[column]
    return chosen if noise is None else chosen.with_noise(noise)


def sensor_set(names, noise: dict | None = None) -> tuple[Sensor, ...]:
    """Sensors in the order of `SENSORS` from ``names`` (a comma-separated string or names), each with the
    noise ``noise[name]`` (column or short name) where given.

    Raises:
        ValueError: no sensor, an unknown or repeated one, or noise for a sensor not chosen.
    """
    listed = [n.strip() for n in names.split(",")] if isinstance(names, str) else [str(n) for n in names]
    listed = [n for n in listed if n]
    if not listed:
        raise ValueError("choose at least one sensor (e.g. pressure,syringe)")
    columns = [sensor(n).column for n in listed]
    repeated = sorted({c for c in columns if columns.count(c) > 1})
    if repeated:
        raise ValueError(f"sensor {repeated[0]} is chosen twice")
    given = {sensor(k).column: float(v) for k, v in (noise or {}).items()}
    stray = sorted(set(given) - set(columns))
    if stray:
        raise ValueError(f"noise given for {stray[0]}, which is not a chosen sensor ({', '.join(columns)})")
    return tuple(sensor(c, given.get(c)) for c in SENSORS if c in columns)


def measurements(experiment: Experiment, chosen: tuple[Sensor, ...]) -> np.ndarray:
    """The chosen sensors' readings (T, m) from ``experiment``'s columns, SI; NaN where a sample is missing.

    Raises:
        ValueError: a chosen sensor whose column the experiment lacks.
    """
    missing = [s.column for s in chosen if s.column not in experiment]
    if missing:
        where = f" {experiment.source}" if experiment.source else ""
        raise ValueError(f"the experiment{where} has no {missing[0]} column for the chosen sensor {missing[0]}")
    return np.stack([np.asarray(experiment[s.column], float) for s in chosen], axis=1)


def parse_noise(text: str | None) -> dict:
    """``pressure=500,syringe=5e-6`` → {name: sd}; ValueError naming a bad entry."""
    out = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        if "=" not in item:
            raise ValueError(f"--noise expects SENSOR=SD entries, got {item!r}")
        name, value = (s.strip() for s in item.split("=", 1))
        try:
            out[sensor(name).column] = float(value)
        except ValueError as err:
            if "unknown sensor" in str(err):
                raise
            raise ValueError(f"--noise {name}: {value!r} is not a number") from None
    return out


__all__ = ["PUMP_SENSORS", "SENSORS", "Sensor", "measurements", "parse_noise", "sensor", "sensor_set"]
