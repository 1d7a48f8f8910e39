"""Latin-hypercube and Sobol sweeps of the model, scored against a measured length, in resumable stores.

A sweep is a box of parameters (`Dimension`), a design of points in it (`latin_hypercube`), and one compiled,
sharded call of the model that scores every point (`evaluate`); `lhs_sweep` keeps its chunks in a store as they
finish, `resume` completes a stopped one and `load` reads one as far as it has run; `sobol_indices` is the
variance-based sensitivity of the scores.
"""

from growjax.sweep._box import Dimension, latin_hypercube, paper_box, parse_dimension
from growjax.sweep._evaluate import (
    FAST,
    INVALID_PARAMETER,
    NOT_RUN,
    QUICK_COMPILE_ROWS,
    REASONS,
    ChunkCallback,
    SweepResult,
    evaluate,
    make_members,
)
from growjax.sweep._sobol import sobol_indices
from growjax.sweep._stored import SweepInterrupted, lhs_sweep, load, resume
from growjax.sweep.store import StoreError

__all__ = [
    "FAST",
    "INVALID_PARAMETER",
    "NOT_RUN",
    "QUICK_COMPILE_ROWS",
    "REASONS",
    "ChunkCallback",
    "Dimension",
    "StoreError",
    "SweepInterrupted",
    "SweepResult",
    "evaluate",
    "latin_hypercube",
    "lhs_sweep",
    "load",
    "make_members",
    "paper_box",
    "parse_dimension",
    "resume",
    "sobol_indices",
]
