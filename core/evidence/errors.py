"""The error raised for bad feature inputs: a ValueError whose message names the problem and the fix."""

from ..errors import InputError


class FeatureInputError(InputError):
    """An image, mask or parameter given to the feature code is unusable (shape, dtype, size, range)."""
