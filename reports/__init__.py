"""Plots and self-contained HTML validation reports."""
