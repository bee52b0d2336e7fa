"""The error type of the `daq` package (a :class:`~flexmodal.checked_io.errors.FlexmodalError`)."""

from flexmodal.checked_io.errors import FlexmodalError


class DaqError(FlexmodalError):
    """Bad input for `daq`: the message names the file, field or value and what is wrong."""
