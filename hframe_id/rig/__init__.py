"""Rigs (simulated and serial hardware), experiment protocols and the crash-safe logger.

Data flow: a ``Rig`` delivers samples and takes voltages; a protocol says which voltage to
command at each sample; ``run_experiment`` runs one against the other with the safety rules
always on and writes the samples through ``hframe_id.recordings.writer``.
"""
