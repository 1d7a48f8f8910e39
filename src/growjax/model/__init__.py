"""The model: the rig's components (fluid, hoses and tank, pump, motor, robot), its parameters and limits, the
catalogue of effects beyond the published model, and the input signals."""
