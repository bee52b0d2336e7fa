"""Vectorised decoding of DBC signals (cantools definitions) over many CAN frames at once.

cantools decodes one frame per call; here the signal layout (start bit, length, byte order, sign,
scale, offset, multiplexer ids) is read once from the cantools database and every signal is extracted
from all frames with integer shifts and masks on a uint64 view of the 8 data bytes.  Intel
(little-endian) signals use the little-endian word with the start bit as LSB position; Motorola
(big-endian) signals use the big-endian word, where the DBC start bit (the MSB, sawtooth numbering:
byte ``start // 8``, bit ``start % 8``) sits at position ``(7 - start // 8) * 8 + start % 8``.
"""

from __future__ import annotations

import codecs
import math
from dataclasses import dataclass

import numpy as np

from flexmodal.checked_io.text import one_line, read_bytes
from flexmodal.daq.errors import DaqError


@dataclass(frozen=True)
class SignalLayout:
    name: str
    lsb: int  # bit position of the LSB in the word of its byte order
    length: int
    big_endian: bool
    signed: bool
    scale: float
    offset: float
    mux_ids: tuple[int, ...] | None  # multiplexer values that carry this signal (None: always present)
    raw_min: int
    raw_max: int
    unit: str = ""  # the DBC's unit of the physical value (free text, '' when none)

    @property
    def limits(self) -> tuple[float, float]:
        """Physical values of the most negative and most positive raw codes."""
        a, b = self.raw_min * self.scale + self.offset, self.raw_max * self.scale + self.offset
        return (min(a, b), max(a, b))


def _layout(sig) -> SignalLayout:
    big = sig.byte_order == "big_endian"
    if big:
        lsb = (7 - sig.start // 8) * 8 + sig.start % 8 - sig.length + 1
    else:
        lsb = sig.start
    if lsb < 0 or lsb + sig.length > 64:
        raise DaqError(f"DBC signal {sig.name!r}: bits outside the 8 data bytes")
    if not (math.isfinite(sig.scale) and sig.scale != 0 and math.isfinite(sig.offset)):
        raise DaqError(f"DBC signal {sig.name!r}: factor {sig.scale!r} and offset {sig.offset!r} must be "
                       "finite, the factor non-zero (a factor 0 decodes every value as the offset)")
    raw_min, raw_max = ((-(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1) if sig.is_signed
                        else (0, (1 << sig.length) - 1))
    return SignalLayout(sig.name, lsb, sig.length, big, sig.is_signed, float(sig.scale), float(sig.offset),
                        tuple(sig.multiplexer_ids) if sig.multiplexer_ids else None, raw_min, raw_max,
                        str(sig.unit or "").strip())


@dataclass(frozen=True)
class MessageLayout:
    """The signals of one DBC message, its multiplexer (if any) and its frame id."""

    frame_id: int
    length: int
    mux: SignalLayout | None
    signals: tuple[SignalLayout, ...]
    name: str = ""
    is_extended_frame: bool = False

    @classmethod
    def from_cantools(cls, message) -> MessageLayout:
        layouts = [_layout(s) for s in message.signals]
        mux = next((lay for lay, s in zip(layouts, message.signals, strict=True) if s.is_multiplexer), None)
        return cls(message.frame_id, message.length, mux,
                   tuple(lay for lay in layouts if lay is not mux), message.name,
                   bool(message.is_extended_frame))

    def signal(self, name: str) -> SignalLayout:
        return next(s for s in self.signals if s.name == name)

    def raw(self, data: np.ndarray, sig: SignalLayout) -> np.ndarray:
        """Raw integer codes of ``sig`` from frames ``data`` [n, 8] uint8."""
        word = data.view("<u8" if not sig.big_endian else ">u8")[:, 0].astype(np.uint64)
        raw = (word >> np.uint64(sig.lsb)) & np.uint64((1 << sig.length) - 1)
        raw = raw.astype(np.int64)
        if sig.signed:
            raw = np.where(raw >= 1 << (sig.length - 1), raw - (1 << sig.length), raw)
        return raw

    def decode(self, data: np.ndarray, sig: SignalLayout) -> np.ndarray:
        """Physical values of ``sig`` in frames ``data`` [n, 8] (NaN where its multiplexer id is absent)."""
        value = self.raw(data, sig) * sig.scale + sig.offset
        if sig.mux_ids is not None and self.mux is not None:
            value = np.where(np.isin(self.raw(data, self.mux), sig.mux_ids), value, np.nan)
        return value


def _encoding(data: bytes) -> str | None:
    """The text encoding of a CAN database's bytes: UTF-8 when they are UTF-8 (with or without a
    byte-order mark), else None (cantools' own default, cp1252 for DBC files, as Vector tools write
    them).  cantools read every file as cp1252: a UTF-8 unit 'µV' became 'Âµ V' (and was then not
    recognised as micro-volts), a byte-order mark a syntax error at line 1.

    Examples
    --------
    >>> _encoding(b"\\xef\\xbb\\xbfVERSION"), _encoding("µV".encode()), _encoding("µV".encode("cp1252"))
    ('utf-8-sig', 'utf-8', None)
    """
    if data.startswith(codecs.BOM_UTF8):
        return "utf-8-sig"
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return None
    return "utf-8"


def _one_message_each(dbc_path: str, messages, chosen) -> None:
    """DaqError when a message the session reads shares its name, or its frame id (standard and
    extended ids apart: 0x100 and extended 0x100 are two frames), with another message of the file:
    cantools keeps both, and a lookup by name or id took one of them in silence.  Duplicates among
    messages the session does not read are no concern of it (a whole vehicle's DBC)."""
    for what, key, show in (("message name", lambda m: m.name, str),
                            ("frame id", lambda m: (m.frame_id, bool(m.is_extended_frame)),
                             lambda k: f"{k[0]:#x}{' (extended)' if k[1] else ''}")):
        keys = [key(m) for m in messages]
        twice = [key(m) for m in chosen if keys.count(key(m)) > 1]
        if twice:
            raise DaqError(f"{dbc_path}: {what} {show(twice[0])} is given to two messages (one per message)")


def load_messages(dbc_path: str, names: list[str] | tuple[str, ...] = ()) -> list[MessageLayout]:
    """The sample-carrying messages of a DBC file: ``names`` in this order, else the only multiplexed
    message (or the only message).  Signal names must be unique over the messages."""
    import cantools

    data = read_bytes(dbc_path, DaqError, "DBC file")   # a FIFO, a device or 1 GB of junk: one line
    try:   # read once; any file name (cantools picks the format by extension: 'x.txt' was refused)
        db = cantools.database.load_string(data.decode(_encoding(data) or "cp1252"), database_format="dbc")
    except Exception as exc:  # cantools raises several parser error types, and UnicodeDecodeError
        raise DaqError(f"{dbc_path}: not a readable DBC file ({one_line(exc)})") from exc
    known = {m.name: m for m in db.messages}
    if names:
        missing = [n for n in names if n not in known]
        if missing:
            raise DaqError(f"{dbc_path}: no message {missing[0]!r} (messages: {', '.join(known)})")
        found = [known[n] for n in names]
    else:
        found = [m for m in db.messages if m.is_multiplexed()] or list(db.messages)
        if len(found) != 1:
            raise DaqError(f"{dbc_path}: name the messages carrying the samples (messages = [...]); "
                           f"messages: {', '.join(known)}")
    _one_message_each(dbc_path, db.messages, found)
    try:
        return [MessageLayout.from_cantools(m) for m in found]
    except DaqError as exc:   # a signal's layout: name the file too
        raise DaqError(f"{dbc_path}: {exc}") from None


def load_message(dbc_path: str, message: str = "") -> MessageLayout:
    """The one sample-carrying message of a DBC file: ``message`` by name, else the only multiplexed one."""
    return load_messages(dbc_path, [message] if message else [])[0]
