"""Rasterising the posed body into each view: reference, fast CPU and GLSL paths."""
