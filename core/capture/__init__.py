"""Capture input: calibration formats, synchronised frames, background plates."""
