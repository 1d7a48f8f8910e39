"""Latin-hypercube and Sobol sweeps of the model, scored against a measured length, in resumable stores."""

from ._sweep import (
    FAST,
    INVALID_PARAMETER,
    NOT_RUN,
    QUICK_COMPILE_ROWS,
    REASONS,
    Dimension,
    SweepInterrupted,
    SweepResult,
    evaluate,
    latin_hypercube,
    lhs_sweep,
    load,
    make_members,
    paper_box,
    parse_dimension,
    resume,
    sobol_indices,
)
from .store import StoreError

__all__ = [
    "Dimension",
    "FAST",
    "INVALID_PARAMETER",
    "NOT_RUN",
    "QUICK_COMPILE_ROWS",
    "REASONS",
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
    "StoreError",
]
