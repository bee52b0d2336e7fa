"""The error type of the `compare` package (a :class:`~flexmodal.checked_io.errors.FlexmodalError`)."""

from flexmodal.checked_io.errors import FlexmodalError


class CompareError(FlexmodalError):
    """Bad input for `compare`: the message names the file, field or value and what is wrong."""
