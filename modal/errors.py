"""The error type of the `modal` package (a :class:`~flexmodal.checked_io.errors.FlexmodalError`)."""

from flexmodal.checked_io.errors import FlexmodalError


class ModalError(FlexmodalError):
    """Bad input for `modal`: the message names the file, field or value and what is wrong."""


