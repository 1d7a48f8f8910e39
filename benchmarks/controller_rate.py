"""Why the stepper controller runs at f = 3 Hz: its own tracking error on the measured length, per rate.

Run: ``python benchmarks/controller_rate.py``. For each f, the shipped step counter
is fed the demand in steps from kings_ts (0–10 s); printed are the steps issued and the RMS of
(step count − demand) over 0–10 s. No ODE solve is involved.
"""

import numpy as np

import growjax as gj
from growjax.data import experiment as ex
from growjax.model.motor import step_schedule


def main():
    folder = ex.shared_experiment_dir()
    if folder is None:
        raise SystemExit("needs ../shared/data/mammobot beside the checkout")
    exp = ex.read(folder / "experiment.csv")
    demand = ex.demand_steps(gj.reference("inverse"), exp["robot_length_m"])
    grid = np.linspace(0.001, 10.0, 2000)
    target = np.interp(grid, exp.time, demand)
    print("f_Hz  steps_issued  rms_error_steps")
    for rate in (1, 2, 3, 4, 5, 8, 10, 20, 100):
        times, counts = step_schedule(demand, exp.time, rate, 0.001, 10.0)
        j = np.searchsorted(times, grid, side="right") - 1
        position = np.where(j >= 0, counts[np.maximum(j, 0)] if counts.size else 0.0, 0.0)
        print(f"{rate:5g}  {times.size:12d}  {np.sqrt(np.mean((position - target) ** 2)):15.3f}")


if __name__ == "__main__":
    main()
