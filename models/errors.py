"""The one error type of the `models` package: its message is the one line the CLI prints (exit 2)."""


class ModelError(ValueError):
    """Bad input for `models`: the message names the file, field or value and what is wrong."""
