"""Fleets of rigs: batch fits on Dask, a Parquet results store, rig history and drift.

The pipeline, one module per step: ``manifest`` (which fits to run) -> ``keys`` (a fit's
identity and options) -> ``job`` (one fit, run on a worker) -> ``runner`` (a Dask client maps
jobs, results arrive as they finish) -> ``store`` (one Parquet row per fit) -> ``drift``
(changes against each rig's first run) -> ``report`` (plots and the flags table).
``synthetic`` makes a fleet with the sim rig; ``studies`` runs study trials on the same
clusters.
"""
