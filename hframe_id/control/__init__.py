"""Closed-loop control of the H-frame (Chapter 5): trajectories, reset-windup PID, metrics."""
