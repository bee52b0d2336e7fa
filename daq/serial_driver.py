"""Serial driver: pyserial ``serial_for_url`` (real ports, ptys, ``loop://``) with binary or CSV framing."""

from __future__ import annotations

import os
import select
import time
from dataclasses import dataclass

import serial

from flexmodal.daq.devices import Block, Device, DeviceLost, Driver, unwrap
from flexmodal.daq.errors import DaqError
from flexmodal.daq.serial_frames import (
    CHECKSUM_BYTES,
    SEQ_MODULUS,
    BinaryDecoder,
    CsvDecoder,
    CustomDecoder,
    FrameSpec,
)

READ_TIMEOUT_S = 0.02
READ_MAX_BYTES = 1 << 20


def _frame_spec(t, n_sources: int) -> FrameSpec:
    """The ``[device.frame]`` table of a custom framing (docs/acquisition.md)."""
    from flexmodal.daq.session import Table

    f = Table(t.get("frame", dict), f"{t.where}: frame")
    f.reject_unknown({"header", "layout", "scans", "counter_bytes", "counter_wrap", "counter_counts",
                      "checksum"})
    header = f.get("header", list, check=lambda v: v and all(isinstance(b, int) and 0 <= b <= 255 for b in v),
                   why="must be a non-empty list of byte values 0..255 (e.g. [0xA5, 0x5A])")
    try:
        spec = FrameSpec(bytes(header), f.get("layout", str), f.get("scans", int, 1),
                         f.get("counter_bytes", int, 0), f.get("counter_wrap", int, 0),
                         f.choice("counter_counts", ("frames", "samples"), "frames"),
                         f.choice("checksum", tuple(CHECKSUM_BYTES), "none"))
    except ValueError as exc:
        raise DaqError(f"{f.where}: {exc}") from None
    if len(spec.codes) != n_sources:
        raise DaqError(f"{f.where}: layout {spec.layout!r} has {len(spec.codes)} values per scan but the "
                       f"device lists {n_sources} sources")
    return spec


@dataclass(frozen=True)
class SerialConfig:
    """A serial device's ``[[device]]`` fields (docs/acquisition.md): ``port`` (a path or pyserial URL),
    ``sources`` (the names of the frame's columns, in order), ``baud``, ``framing`` (binary, csv or
    custom), ``frame`` (the custom framing's FrameSpec) and ``checksum`` (csv lines)."""

    port: str
    sources: tuple[str, ...]
    baud: int = 115200
    framing: str = "binary"
    frame: FrameSpec | None = None
    checksum: str = "none"


class SerialDriver(Driver):
    """A device streaming binary frames or CSV lines; sample index from the frame sequence counter."""

    protocol = "serial"

    @classmethod
    def parse_device(cls, t, name):
        """``port`` (path or pyserial URL), ``baud``, ``framing``, ``sources`` (the frame's columns)."""
        t.reject_unknown({"port", "baud", "framing", "sources", "frame", "checksum"})
        port = t.port("port")
        sources = t.get("sources", list, check=lambda v: v and all(isinstance(s, str) for s in v),
                        why="must be a non-empty list of column names")
        framing = t.choice("framing", ("binary", "csv", "custom"), "binary")
        frame = _frame_spec(t, len(sources)) if framing == "custom" else None
        if "frame" in t.doc and framing != "custom":
            raise DaqError(f"{t.where}: [device.frame] needs framing = \"custom\"")
        check = t.choice("checksum", tuple(CHECKSUM_BYTES), "none")
        if check != "none" and framing != "csv":
            raise DaqError(f"{t.where}: checksum is for framing = \"csv\" (custom frames: frame.checksum)")
        return Device(name, cls.protocol, SerialConfig(port, tuple(sources), t.get("baud", int, 115200),
                                                       framing, frame, check))

    def __init__(self, device, sample_rate_hz: float) -> None:
        self.name = device.name
        self.sample_rate_hz = sample_rate_hz
        self.config = device.config
        self.sources = device.config.sources
        self.limits = None  # raw formats are self-describing; clipping is judged on full_scale
        self._port = None
        self._last: int | None = None
        self._new_decoder()

    def _new_decoder(self) -> None:
        n, d = len(self.sources), self.config
        self._decoder = (BinaryDecoder(n) if d.framing == "binary" else CsvDecoder(n, d.checksum)
                         if d.framing == "csv" else CustomDecoder(d.frame))

    def open(self) -> None:
        """Open the port exclusively (POSIX: an advisory lock): a second reader of the same port, e.g.
        another session, or a reconnect through a stale path that now names another device's pty, fails
        to open (and retries) instead of silently taking part of the stream."""
        try:
            self._port = serial.serial_for_url(self.config.port, baudrate=self.config.baud,
                                               timeout=READ_TIMEOUT_S, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            raise DeviceLost(f"cannot open {self.config.port}: {exc}") from exc
        self._new_decoder()  # a partial frame from before a reconnect is garbage

    def _read_bytes(self) -> bytes:
        """What has arrived (waiting up to the timeout for the first byte).

        On a POSIX port the file descriptor is drained directly (many kernel buffers per call, no
        bytes held inside pyserial when the port vanishes); other URLs use pyserial's read.
        """
        fd = getattr(self._port, "fd", None)
        if fd is None:
            data = self._port.read(1)
            return data + self._port.read(self._port.in_waiting) if data else b""
        chunks, size, timeout = [], 0, READ_TIMEOUT_S
        while size < READ_MAX_BYTES and select.select([fd], [], [], timeout)[0]:
            try:
                chunk = os.read(fd, READ_MAX_BYTES)
            except OSError:
                if chunks:
                    break  # hand over what arrived; the next read reports the loss
                raise
            if not chunk:
                if chunks:
                    break
                raise serial.SerialException("device reports readiness to read but returned no data")
            chunks.append(chunk)
            size += len(chunk)
            timeout = 0.0
        return b"".join(chunks)

    def read(self) -> list[Block]:
        try:
            data = self._read_bytes()
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            raise DeviceLost(f"{self.config.port}: {exc}") from exc
        now = time.time()
        if not data:
            return []
        blocks = []
        modulus = SEQ_MODULUS if self.config.framing == "binary" else 1 << 62  # others: unwrapped
        for seq, values, corrupt in self._decoder.feed(data):
            first = unwrap(seq, self._last, modulus)
            self._last = first + values.shape[0]
            blocks.append(Block(self.name, first, values, now, corrupt))
        if blocks:  # the newest sample arrived about now: date the first sample of each block from it
            end = blocks[-1].first_index + blocks[-1].values.shape[0]
            for b in blocks:
                b.timestamp_s = now - (end - b.first_index) / self.sample_rate_hz
        return blocks

    def close(self) -> None:
        if self._port is not None:
            try:
                self._port.close()
            except (serial.SerialException, OSError):
                pass
            self._port = None
