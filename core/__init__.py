"""The engine: NumPy, SciPy and OpenCV only. Never imports bpy."""
