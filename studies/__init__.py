"""Studies of the estimators on simulated plants and real data (the measurements behind
docs/fitting.md and docs/studies/), run from the checkout (``python -m studies.<name>``); not
shipped in the package."""
