"""The one error type of the `daq` package: its message is the one line the CLI prints (exit 2)."""


class DaqError(ValueError):
    """Bad input for `daq`: the message names the file, field or value and what is wrong."""
