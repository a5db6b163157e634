"""Benchmark sections run from the checkout (``python -m bench.<name>``, second command of
``make bench``), not shipped in the package."""
