"""Facial landmarks on a scan, tied to template vertices: MediaPipe on colour or on renders, or none."""
