"""Open- and closed-loop simulation of the models."""
