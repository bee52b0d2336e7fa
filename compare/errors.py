"""The one error type of the `compare` package: its message is the one line the CLI prints (exit 2)."""


class CompareError(ValueError):
    """Bad input for `compare`: the message names the file, field or value and what is wrong."""
