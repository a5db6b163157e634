"""Linear analysis of the models about rest."""
