"""Identification of the elastostatic parameters: the least-squares core, the linear,
two-step and nonlinear methods, the result type, gross-error detection, the host-side
entry `identify` and calibrated robot files."""
