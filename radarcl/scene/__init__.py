"""Simulation: the FMCW beat-signal simulator and (later) the reference scene with ground truth."""
