"""Comparison of measured and predicted modes, tables and sim-to-real gap diagnosis."""
