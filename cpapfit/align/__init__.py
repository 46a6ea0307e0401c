"""Alignment of the template to a scan: similarity (rigid + scale) and non-rigid."""
