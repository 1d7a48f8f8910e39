"""Calibration: the likelihood (discrepancy, noise, the rig's tolerances), least squares, and the fit of an
experiment set."""
