"""Open-loop simulation of the models: RK4 with substeps over zero-order-held samples, smooth or
stick-slip friction, optional native code (docs/friction.md). Closed loop: ``hframe_id.control``.
"""
