"""Solving the model: the configurations (fast and reference), their solvers, `simulate` and the
trajectories it returns.

The package re-exports nothing: its entry points are `growjax.simulate`, `growjax.simulate_members`,
`growjax.Config` and `growjax.Trajectory`, and each module declares its own public names (a re-export of the
function `simulate` here would hide the module `growjax.simulation.simulate`).
"""
