"""Model validation as control engineers know it from MATLAB's ``compare`` and ``resid``:
simulation fit [%], k-step-ahead prediction fit [%], residual whiteness and independence from
the inputs with 99 % bands, plots, and leave-one-recording-out cross-validation
(docs/validation.md).
"""
