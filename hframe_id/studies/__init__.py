"""Studies of the estimators on simulated plants (measurements behind docs/fitting.md)."""
