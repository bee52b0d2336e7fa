"""The one registry shape of flexmodal: named entries of one kind (FRF estimators, identification methods,
models, effects, acquisition protocols), each family exposing ``register_x`` / ``unregister_x`` /
``registered_x()`` over a :class:`Registry`.

Built-in entries may be given as ``"module:attribute"`` strings, imported on first use: listing the names
(``--help``, argparse ``choices``) imports nothing, so the command line starts fast and the names are
kept in one place only.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping, MutableMapping
from typing import Generic, TypeVar

from flexmodal.checked_io.errors import FlexmodalError

T = TypeVar("T")


class Registry(MutableMapping[str, T], Generic[T]):
    """Entries of one ``kind`` by name, in registration order.

    Parameters
    ----------
    kind : str
        What an entry is ("model", "FRF estimator", ...), for the error message of an unknown name.
    error : type of FlexmodalError
        The package's error type raised for an unknown name.
    builtins : mapping of str to entry or str
        The entries shipped; a ``"module:attribute"`` string is imported when first looked up.
    fold_case : bool
        Match names without regard to case (registering ``h1`` replaces ``H1``).

    Examples
    --------
    >>> from flexmodal.modal.errors import ModalError
    >>> colours = Registry("colour", ModalError, {"red": "operator:neg"})
    >>> colours.register("blue", abs) is abs
    True
    >>> list(colours), colours["red"](2)
    (['red', 'blue'], -2)
    >>> colours.unregister("blue")
    >>> colours.entry("green")
    Traceback (most recent call last):
    ...
    flexmodal.modal.errors.ModalError: unknown colour 'green' (expected one of red)
    """

    def __init__(self, kind: str, error: type[FlexmodalError], builtins: Mapping[str, T | str] | None = None,
                 *, fold_case: bool = False) -> None:
        self.kind, self.error, self.fold_case = kind, error, fold_case
        self._entries: dict[str, T | str] = dict(builtins or {})

    def _key(self, name: object) -> str | None:
        if name in self._entries:
            return str(name)
        if self.fold_case:
            return next((k for k in self._entries if k.lower() == str(name).lower()), None)
        return None

    def name(self, name: str) -> str:
        """The registered spelling of ``name``; the package's error naming the choices otherwise."""
        key = self._key(name)
        if key is None:
            raise self.error(f"unknown {self.kind} {name!r} (expected one of {', '.join(self._entries)})")
        return key

    def entry(self, name: str) -> T:
        """The entry of ``name`` (imported on first use); the package's error naming the choices when
        there is none (``registry[name]`` raises KeyError instead, as a mapping does)."""
        return self[self.name(name)]

    def register(self, name: str, entry: T | str) -> T | str:
        """Add ``entry`` as ``name`` (a name already registered, in any case when folding, is replaced
        in place); returns ``entry``."""
        known = self._key(name)
        if known is not None and known != name:   # another spelling: renamed where it stands
            self._entries = {name if k == known else k: v for k, v in self._entries.items()}
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Remove ``name``; the package's error when it is not registered."""
        del self._entries[self.name(name)]

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order (nothing is imported)."""
        return tuple(self._entries)

    def __getitem__(self, name: str) -> T:
        key = self._key(name)
        if key is None:
            raise KeyError(name)
        entry = self._entries[key]
        if isinstance(entry, str):
            module, _, attr = entry.partition(":")
            entry = self._entries[key] = getattr(importlib.import_module(module), attr)
        return entry

    def __contains__(self, name: object) -> bool:
        return self._key(name) is not None

    def __setitem__(self, name: str, entry: T | str) -> None:
        self.register(name, entry)

    def __delitem__(self, name: str) -> None:
        self.unregister(name)

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(self._entries))

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._entries)})"
