"""The one error family of flexmodal: bad input, worded as the one line the CLI prints (exit 2).

Each package raises its own subclass (``DaqError``, ``ModalError``, ``ModelError``, ``CompareError``,
``ReportError``, ``FixtureError`` in its ``errors.py``), so a caller can catch one package's errors or,
with :class:`FlexmodalError`, all of them.
"""


class FlexmodalError(ValueError):
    """Bad input: the message names the file, field or value and what is wrong (one line).

    Examples
    --------
    >>> from flexmodal.modal.errors import ModalError
    >>> issubclass(ModalError, FlexmodalError)
    True
    """
