"""The error type of the `reports` package (a :class:`~flexmodal.checked_io.errors.FlexmodalError`)."""

from flexmodal.checked_io.errors import FlexmodalError


class ReportError(FlexmodalError):
    """Bad input for `reports`: the message names the file, field or value and what is wrong."""
