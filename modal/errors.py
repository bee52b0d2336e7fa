"""The one error type of the `modal` package: its message is the one line the CLI prints (exit 2)."""


class ModalError(ValueError):
    """Bad input for `modal`: the message names the file, field or value and what is wrong."""
