"""Experiment design: which excitation to record so that a fit identifies the parameters.

``information`` predicts what a fit of an experiment would know (the fitter's own
transcription and sensitivities), ``criteria`` scores it, ``excitation`` parameterises the
motors' voltages, ``optimise`` chooses within the rig's limits, ``baselines`` are the
experiments a design is compared with, ``report`` writes what a design predicts.
"""
