"""The error type of the `models` package (a :class:`~flexmodal.checked_io.errors.FlexmodalError`)."""

from flexmodal.checked_io.errors import FlexmodalError


class ModelError(FlexmodalError):
    """Bad input for `models`: the message names the file, field or value and what is wrong."""
