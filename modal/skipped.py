"""The error of a batch over many runs that skipped its bad runs and did the good ones (``frf``,
``identify``): :class:`RunsFailed`, a ModalError that carries what was done."""

from flexmodal.modal.errors import ModalError


class RunsFailed(ModalError):
    """Some runs of a batch (``frf`` or ``identify`` over many runs) were bad and skipped; the good ones
    were done and written.  The message is one line naming every bad run and why.

    Attributes
    ----------
    written : list
        What was done: ``frf``, the (file, run id) pairs written; ``identify``, the configurations
        identified.
    failed : list of (str, Exception)
        For each bad run, in input order: ``FILE:RUN_ID`` (or ``FILE`` when the file itself is bad) and
        the error that stopped it.
    result : object or None
        What the call returns otherwise (``identify``: the Identification of the good runs), else None.

    Examples
    --------
    >>> bad = [("a.h5:r1", ModalError("a.h5:r1: channel 'f' is constant")),
    ...        ("a.h5:r2", ModalError("record of 100 samples is shorter than one segment"))]
    >>> print(RunsFailed([("a.h5", "r0")], bad[:1]))
    a.h5:r1: channel 'f' is constant (skipped; the other 1 run done)
    >>> for line in RunsFailed([("a.h5", "r0")], bad).lines():
    ...     print(line)
    a.h5:r1: channel 'f' is constant
    a.h5:r2: record of 100 samples is shorter than one segment
    2 of 3 runs skipped (each named above), the other 1 done
    """

    def __init__(self, written, failed, result=None) -> None:
        self.written, self.failed, self.result = list(written), list(failed), result
        if len(self.failed) == 1:
            n_ok = len(self.written)
            others = f" (skipped; the other {n_ok} run{'s' * (n_ok != 1)} done)" if n_ok else ""
            message = self._why(0) + others
        else:
            message = self.summary().replace(" (each named above)", "") + ": " + "; ".join(
                self._why(k) for k in range(len(self.failed)))
        super().__init__(message)

    def _why(self, k: int) -> str:
        """Bad run ``k``'s error as one line that names it."""
        name, error = self.failed[k]
        text = " ".join(str(error).split())
        return text if name.rsplit(":", 1)[-1] in text else f"{name}: {text}"

    def summary(self) -> str:
        """``N of M runs skipped ...``: the one line that ends the list of bad runs."""
        n_bad, n_ok = len(self.failed), len(self.written)
        return f"{n_bad} of {n_bad + n_ok} runs skipped (each named above), the other {n_ok} done"

    def lines(self) -> list[str]:
        """The lines the CLI prints on stderr: each bad run and why, then one summary line (one bad run:
        its one line)."""
        if len(self.failed) == 1:
            return [str(self)]
        return [*(self._why(k) for k in range(len(self.failed))), self.summary()]
