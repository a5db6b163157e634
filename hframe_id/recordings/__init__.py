"""Recordings: the MCAP log format, its reader and writer, rigs and the logger."""
