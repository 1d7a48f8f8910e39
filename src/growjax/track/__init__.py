"""Tracking: the calibrated model as a live estimator of the robot's length, pressure, parameters and unrecorded
inputs, from the rig's own sensors.

What is here, in the order a tracker uses it:

* `growjax.track.sensors` — the rig's sensors (pressure, syringe displacement, inlet flow, catheter and robot
  length), their columns and noise.
* `growjax.track.noise` — the uncertainty the filter starts from and adds, from calibration: the rig's
  tolerances as static states, parameters and unrecorded inputs as random walks, the length discrepancy as the
  Matérn-3/2 process a fit found.
* `state_space` / `StateSpace` — the fast configuration as a discrete-time state-space system: the
  state advanced over a sample interval by the configuration's own solver, the sensors read from it.
* `ExtendedKalman` (the default) and `Unscented` — the filters; `Filter` compiles a method's
  step once for a control loop to call once per sample.
* `smooth` — the Rauch–Tung–Striebel smoother over a filtered record.
* `track` — a whole record tracked (causal, or smoothed), read into `TrackResult`: the length,
  pressure, parameters and inputs with 90 % bands, their CSV and the score against a measured length.
* `watch` — a record watched for a sudden change (a CUSUM on the innovations), each change flagged with its
  time and named among the catalogue's effects by a bank of filters: `Watch`, `Change`.
* `track_figure` — its figure.
"""

from growjax.track.belief import Belief, Step
from growjax.track.change import CANDIDATES, Candidate, Change, Cusum, Watch, watch, watch_model
from growjax.track.extended import ExtendedKalman
from growjax.track.filter import Filter
from growjax.track.model import StateSpace, state_space
from growjax.track.noise import Discrepancy, InputState, StateParameter
from growjax.track.result import TrackResult
from growjax.track.run import track
from growjax.track.sensors import PUMP_SENSORS, SENSORS, Sensor, sensor, sensor_set
from growjax.track.smoother import smooth
from growjax.track.unscented import Unscented

__all__ = [
    "CANDIDATES",
    "PUMP_SENSORS",
    "SENSORS",
    "Belief",
    "Candidate",
    "Change",
    "Cusum",
    "Discrepancy",
    "ExtendedKalman",
    "Filter",
    "InputState",
    "Sensor",
    "StateParameter",
    "StateSpace",
    "Step",
    "TrackResult",
    "Unscented",
    "Watch",
    "sensor",
    "sensor_set",
    "smooth",
    "state_space",
    "track",
    "watch",
    "watch_model",
]
