"""The one error type of the `reports` package: its message is the one line the CLI prints (exit 2)."""


class ReportError(ValueError):
    """Bad input for `reports`: the message names the file, field or value and what is wrong."""
