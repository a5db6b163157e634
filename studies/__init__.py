"""Studies run from the checkout (``python -m studies.<name>``), not shipped in the package."""
