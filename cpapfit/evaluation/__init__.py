"""Fit evaluation: gaps between cushion and face (pressure and leak: issue 6)."""
