"""Open-loop simulation of the models: RK4 with substeps over zero-order-held samples, smooth or
stick-slip friction, optional native code (docs/friction.md). Closed loop: ``hframe_id.control``.
"""

#: Most RK4 substeps per sample a simulation may take, asked for (``--substeps``) or chosen
#: for stability (``integrators.stable_substeps``): the automatic choice is 4-30 at 1 ms and
#: 600 for the realistic plant at 10 ms; 10^8 made a 50-sample run take minutes, and the
#: count for an inertia of 1e-300 kg m^2 built its expression for ever (gigabytes, deaf to
#: Ctrl-C). Kept here, free of imports, for the command line's option checks.
MAX_SUBSTEPS = 10_000
