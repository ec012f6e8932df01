"""The error raised for bad feature inputs: a ValueError whose message names the problem and the fix."""


class FeatureInputError(ValueError):
    """An image, mask or parameter given to the feature code is unusable (shape, dtype, size, range)."""
