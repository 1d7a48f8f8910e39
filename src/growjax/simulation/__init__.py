"""Solving the model: the configurations (fast and reference), their solvers, :func:`simulate` and the
trajectories it returns."""
