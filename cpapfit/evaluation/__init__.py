"""Fit evaluation: where a cushion meets the face, the tissue under it, its pressure, leak and seal, awake and asleep."""
