"""Synthetic subjects with ground truth: faces made, posed before a virtual depth camera and rendered."""
