"""The error type of the `contract` package (a :class:`~flexmodal.checked_io.errors.FlexmodalError`)."""

from flexmodal.checked_io.errors import FlexmodalError


class ContractError(FlexmodalError):
    """A modal table that breaks the contract: the message names the file, row, column or value."""
