"""Serial stream protocols: the flexmodal binary frame and ASCII CSV lines, encoded and decoded in bulk.

Binary frame (all fields little-endian), docs/acquisition.md:

    offset  size  field
    0       2     sync word 0xA5 0x5A
    2       4     seq: device sample index of the frame's first scan (uint32, wraps)
    6       1     n_ch: channels per scan (1..255)
    7       1     fmt: 1 int16, 2 int32, 3 float32
    8       2     n_scans: scans in the frame (1..65535)
    10      P     payload: n_scans x n_ch samples, scan-major (P = n_scans * n_ch * size)
    10+P    2     CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over bytes 2 .. 10+P-1

CSV line: ``<seq>,<v1>,...,<v_n_ch>\\n`` with seq the sample index (decimal) and values decimal numbers.

Decoding works on whatever bytes arrived: sync candidates are found with numpy, headers of all
candidates are read at once, the CRC of each candidate is checked with ``binascii.crc_hqx`` (C), and the
payloads of all good frames are converted with one ``np.frombuffer`` per run of equal-shape frames.
Bytes that belong to no good frame are counted as corrupt frames; the unfinished tail is kept for the
next call, so frames split across reads are joined.
"""

from __future__ import annotations

import binascii
import re
from dataclasses import dataclass

import numpy as np

SYNC = b"\xa5\x5a"  # the sync word, first two bytes of every frame
HEADER_BYTES = 10
CRC_BYTES = 2
FORMATS = {1: np.dtype("<i2"), 2: np.dtype("<i4"), 3: np.dtype("<f4")}
FORMAT_CODES = {"int16": 1, "int32": 2, "float32": 3}
SEQ_MODULUS = 2**32
FRESH_LINES = 16  # CSV lines a freshly opened stream may wait for to judge its first line by a good later one
HEADER_DTYPE = np.dtype([("sync", "<u2"), ("seq", "<u4"), ("n_ch", "u1"), ("fmt", "u1"), ("n_scans", "<u2")])


def crc16(data: bytes | memoryview) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection): check value 0x29B1 for '123456789'."""
    return binascii.crc_hqx(data, 0xFFFF)


def encode_frames(first_seq: int, samples: np.ndarray, scans_per_frame: int, fmt: str = "int16") -> bytes:
    """Binary frames for consecutive scans ``samples`` [n, n_ch] starting at sample index ``first_seq``.

    ``n`` must be a multiple of ``scans_per_frame``.
    """
    n, n_ch = samples.shape
    if n % scans_per_frame:
        raise ValueError(f"{n} scans are not a multiple of {scans_per_frame} scans per frame")
    dtype = FORMATS[FORMAT_CODES[fmt]]
    n_frames = n // scans_per_frame
    payload = samples.astype(dtype).reshape(n_frames, scans_per_frame * n_ch).view(np.uint8)
    header = np.zeros(n_frames, HEADER_DTYPE)
    header["sync"] = int.from_bytes(SYNC, "little")
    header["seq"] = (first_seq + scans_per_frame * np.arange(n_frames)) % SEQ_MODULUS
    header["n_ch"], header["fmt"], header["n_scans"] = n_ch, FORMAT_CODES[fmt], scans_per_frame
    body = np.concatenate([header.view(np.uint8).reshape(n_frames, HEADER_BYTES), payload], axis=1)
    crc = np.array([crc16(row[2:].tobytes()) for row in body], "<u2").view(np.uint8).reshape(n_frames, 2)
    return np.concatenate([body, crc], axis=1).tobytes()


class BinaryDecoder:
    """Incremental decoder of the binary frame protocol for a device with ``n_ch`` channels."""

    def __init__(self, n_ch: int, max_scans: int = 4096) -> None:
        self.n_ch = n_ch
        self.max_scans = max_scans
        self._buf = b""
        self._garbage = 0  # bytes after the last good frame that belong to no frame
        self._joined = False  # until the first good frame, bytes before it are a partial frame, not corrupt

    def feed(self, data: bytes) -> list[tuple[int, np.ndarray, int]]:
        """Decode ``data`` appended to the kept tail.

        Returns runs of good frames contiguous in seq as ``(first_seq, samples [n, n_ch] float64,
        corrupt_frames_before)``.  A frame is bad when its header is implausible or its CRC fails; the
        bytes between good frames are counted as ``ceil(bytes / frame length)`` corrupt frames.
        """
        buf = self._buf + data
        arr = np.frombuffer(buf, np.uint8)
        if arr.size == 0:
            return []
        starts = np.flatnonzero((arr[:-1] == SYNC[0]) & (arr[1:] == SYNC[1]))
        whole_header = starts + HEADER_BYTES <= arr.size
        s = starts[whole_header]
        head = np.ascontiguousarray(arr[s[:, None] + np.arange(HEADER_BYTES)]).view(HEADER_DTYPE)[:, 0]
        ok = (head["n_ch"] == self.n_ch) & np.isin(head["fmt"], list(FORMATS))
        ok &= (head["n_scans"] >= 1) & (head["n_scans"] <= self.max_scans)
        size = np.array([1, 2, 4, 4])[np.where(ok, head["fmt"], 0)]
        length = HEADER_BYTES + head["n_scans"].astype(np.int64) * self.n_ch * size + CRC_BYTES
        complete = s + length <= arr.size
        check = np.flatnonzero(ok & complete)
        good = np.zeros(s.size, bool)
        if check.size:
            tail = np.ascontiguousarray(arr[(s + length - CRC_BYTES)[check, None] + np.arange(2)])
            crc_in = tail.view("<u2")[:, 0]
            good[check] = [crc16(buf[a + 2:a + n - 2]) == c
                           for a, n, c in zip(s[check], length[check], crc_in, strict=True)]
        gi = np.flatnonzero(good)
        g_start, g_len = s[gi], length[gi]
        g_end = g_start + g_len
        last_end = int(g_end[-1]) if gi.size else 0
        pending = np.concatenate([starts[~whole_header], s[ok & ~complete]])
        pending = pending[pending >= last_end]
        cut = int(pending.min()) if pending.size else arr.size - int(arr[-1] == SYNC[0])
        cut = max(cut, last_end)
        self._buf = buf[cut:]
        if not gi.size:
            self._garbage += cut if self._joined else 0
            return []
        garbage = g_start - np.r_[0, g_end[:-1]]
        garbage[0] = garbage[0] + self._garbage if self._joined else 0
        self._joined = True
        self._garbage = cut - last_end
        corrupt = -(-garbage // g_len)  # ceil
        seq, fmt = head["seq"][gi].astype(np.int64), head["fmt"][gi]
        n_scans = head["n_scans"][gi].astype(np.int64)
        follows = (seq[1:] == (seq[:-1] + n_scans[:-1]) % SEQ_MODULUS) & (fmt[1:] == fmt[:-1])
        follows &= (g_len[1:] == g_len[:-1]) & (garbage[1:] == 0)
        split = np.flatnonzero(~follows) + 1
        runs = []
        for a, b in zip(np.r_[0, split], np.r_[split, gi.size], strict=True):  # one per run of frames
            frames = arr[g_start[a]:g_end[b - 1]].reshape(b - a, g_len[a])  # back to back, equal length
            payload = np.ascontiguousarray(frames[:, HEADER_BYTES:g_len[a] - CRC_BYTES])
            values = payload.view(FORMATS[int(fmt[a])]).reshape(-1, self.n_ch).astype(np.float64)
            runs.append((int(seq[a]), values, int(corrupt[a])))
        return runs


class CsvDecoder:
    """Incremental decoder of CSV lines ``seq,v1,..,v_n`` for ``n_ch`` channels, optionally ending in a
    checksum field (``checksum`` sum8|crc16|crc32: hex digits, an optional ``*`` before them, over the
    bytes of the line before that field's comma).

    Isolated wrong sequence numbers (a flipped digit no checksum caught) are repaired from their
    neighbours (:func:`repair_counters`); a last line off the sequence waits for the next read.  The
    first line after opening is taken only if the first good line after it, k lines on, is k samples
    on (the lines between are then counted as corrupt): a port opened mid-stream (pyserial flushes the
    input on open) may start inside a line, and a line cut inside its counter still parses, as a
    sample with a wrong index (one invented sample and a false gap behind it).
    """

    def __init__(self, n_ch: int, checksum: str = "none") -> None:
        self.n_ch = n_ch
        self.checksum = checksum
        self._buf = b""
        self._garbage = 0
        self._joined = False  # the first (maybe partial) line after opening is not counted as corrupt
        self._fresh = True  # the first line after opening is not judged yet (it may be a cut one)
        self._last: int | None = None  # sequence number of the last good line
        self.repaired = 0

    def _checked(self, lines: list[bytes]) -> tuple[list[bytes], np.ndarray]:
        """Lines without their checksum field, and whether the checksum matched (per line: a C call)."""
        if self.checksum == "none":
            return lines, np.ones(len(lines), bool)
        body, ok = [], np.zeros(len(lines), bool)
        for i, line in enumerate(lines):
            text, _, tail = line.rstrip(b"\r").rpartition(b",")
            body.append(text)
            try:
                ok[i] = bool(text) and int(tail.lstrip(b"*"), 16) == checksum(self.checksum, text)
            except ValueError:
                pass
        return body, ok

    def feed(self, data: bytes) -> list[tuple[int, np.ndarray, int]]:
        """Same result as :meth:`BinaryDecoder.feed`; a bad line counts as one corrupt frame."""
        buf = self._buf + data
        cut = buf.rfind(b"\n") + 1
        self._buf = buf[cut:]
        raw = buf[:cut].split(b"\n")[:-1]
        if not raw:
            return []
        lines, summed = self._checked(raw)
        fields = [line.split(b",") for line in lines]
        shape_ok = np.array([len(f) == self.n_ch + 1 for f in fields]) & summed
        table = np.full((len(lines), self.n_ch + 1), np.nan)
        rows = np.flatnonzero(shape_ok)
        if rows.size:
            flat = b",".join(b",".join(fields[i]) for i in rows).replace(b"\r", b"")
            try:
                table[rows] = np.array(flat.split(b","), dtype=float).reshape(rows.size, -1)
            except ValueError:  # some field is not a number: parse line by line to find which
                for i in rows:
                    try:
                        table[i] = np.array(fields[i], dtype=float)
                    except ValueError:
                        shape_ok[i] = False
        good = shape_ok & np.isfinite(table).all(axis=1) & (table[:, 0] >= 0) & (table[:, 0] % 1 == 0)
        if self._fresh:  # the first line after opening may be the tail of a line the port's flush cut
            later = np.flatnonzero(good[1:]) + 1  # (cut in its counter it parses: '764,...' read as
            if not later.size and len(lines) < FRESH_LINES:  # sample 4): it is trusted only when the
                self._buf = buf  # first good line after it, k lines on, is k samples on; the lines
                return []  # between are then counted as corrupt (a bad checksum right after opening)
            k = int(later[0]) if later.size else 0
            good[0] &= k > 0 and table[k, 0] == table[0, 0] + k
            self._fresh = False
        gi = np.flatnonzero(good)
        seq = table[gi, 0].astype(np.int64)
        if gi.size and gi[-1] == len(lines) - 1:  # a last line off the sequence is judged with the next read
            before = seq[-2] if gi.size > 1 else self._last
            if before is not None and seq[-1] != before + 1:
                self._buf = buf[cut - len(raw[-1]) - 1:]
                good[gi[-1]] = False
                lines, gi, seq = lines[:-1], gi[:-1], seq[:-1]
                good = good[:-1]
        if seq.size:
            prev = self._last if self._last is not None else seq[0] - 1
            fixed, n = repair_counters(np.r_[prev, seq], 1)
            seq = fixed[1:]
            self.repaired += n
            self._last = int(seq[-1])
        if not len(lines):
            return []
        counted = ~good
        if not self._joined:  # lines before the first good one: the partial line we joined in
            counted[:np.argmax(good) if good.any() else good.size] = False
            self._joined = bool(good.any())
        bad_before = np.cumsum(counted) + self._garbage
        n_bad = np.diff(np.concatenate([[0], bad_before[gi]]))
        split = np.flatnonzero((np.diff(seq) != 1) | (n_bad[1:] > 0)) + 1
        runs = [(int(seq[a]), table[gi[a:b], 1:], int(n_bad[a]))
                for a, b in zip(np.r_[0, split], np.r_[split, gi.size], strict=True) if b > a]
        self._garbage = int(bad_before[-1] - (bad_before[gi[-1]] if gi.size else 0)) if self._joined else 0
        return runs


def encode_csv(first_seq: int, values: np.ndarray, checksum_kind: str = "none") -> bytes:
    """CSV lines for scans ``values`` [n, n_ch] starting at sample index ``first_seq`` (with a checksum
    field as :class:`CsvDecoder` reads it unless ``checksum_kind`` is none)."""
    seq = np.arange(first_seq, first_seq + values.shape[0])
    table = np.column_stack([seq, values])
    lines = [",".join(f"{v:.10g}" for v in row) for row in table]
    if checksum_kind != "none":
        width = 2 * CHECKSUM_BYTES[checksum_kind]
        lines = [f"{line},*{checksum(checksum_kind, line.encode()):0{width}X}" for line in lines]
    return "".join(line + "\n" for line in lines).encode()


# -- frames declared in the session (real devices with their own layout) --------------------------------

CHECKSUM_BYTES = {"none": 0, "sum8": 1, "crc16": 2, "crc32": 4}
SAMPLE_CODES = "bBhHiIqQefd"  # struct codes a sample may have (fixed sizes, no padding)
COUNTER_CODES = {1: "B", 2: "H", 4: "I", 8: "Q"}
MAX_SCAN_VALUES = 4096  # values in one scan of a declared layout (a 4096-channel ADC is far beyond any rig)


def checksum(kind: str, data: bytes | memoryview) -> int:
    """``sum8`` (byte sum mod 256), ``crc16`` (CRC-16/CCITT-FALSE) or ``crc32`` (zlib/ISO-HDLC, check
    value 0xCBF43926 for '123456789') of ``data``."""
    if kind == "sum8":
        return sum(bytes(data)) & 0xFF
    if kind == "crc16":
        return crc16(data)
    return binascii.crc32(data)


@dataclass(frozen=True)
class FrameSpec:
    """A fixed-length frame declared in the session: ``header`` bytes, an unsigned counter of
    ``counter_bytes`` (0: none) wrapping at ``counter_wrap`` (0: 2**(8*counter_bytes)) that counts
    ``frames`` or ``samples``, ``scans`` scans of ``layout`` (byte order ``<``/``>`` then struct codes,
    e.g. ``"<12h"``), then a ``checksum`` over counter and samples in the layout's byte order.

    ``ValueError`` names what is wrong.
    """

    header: bytes
    layout: str
    scans: int = 1
    counter_bytes: int = 0
    counter_wrap: int = 0
    counter_counts: str = "frames"
    checksum: str = "none"

    def __post_init__(self) -> None:
        if not self.header:
            raise ValueError("header must have at least one byte (frames are found by it)")
        body = self.layout[1:]
        if self.layout[:1] not in ("<", ">") or not re.fullmatch(rf"(\d*[{SAMPLE_CODES}])+", body):
            # no order given was read as '<' in silence: a big-endian device then decoded as noise
            raise ValueError(f"layout {self.layout!r} is not a byte order < or > and struct codes "
                             f"of {SAMPLE_CODES} (e.g. '<12h')")
        n_values = sum(int(n or 1) for n, _ in re.findall(rf"(\d*)([{SAMPLE_CODES}])", body))
        if n_values > MAX_SCAN_VALUES:  # counted before a scan's codes are spelled out one by one
            raise ValueError(f"layout {self.layout!r} declares {n_values} values per scan (at most "
                             f"{MAX_SCAN_VALUES})")
        if self.counter_bytes not in (0, *COUNTER_CODES):
            raise ValueError(f"counter_bytes {self.counter_bytes} is not 0, 1, 2, 4 or 8")
        if self.checksum not in CHECKSUM_BYTES:
            raise ValueError(f"checksum {self.checksum!r} is not one of {', '.join(CHECKSUM_BYTES)}")
        if not 1 <= self.scans <= 65535:
            raise ValueError(f"scans {self.scans} is not in 1..65535")
        if self.counter_counts not in ("frames", "samples"):
            raise ValueError(f"counter_counts {self.counter_counts!r} is not frames or samples")
        if self.counter_wrap < 0 or self.counter_wrap > 1 << (8 * self.counter_bytes):
            raise ValueError(f"counter_wrap {self.counter_wrap} does not fit {self.counter_bytes} bytes")

    @property
    def order(self) -> str:
        return ">" if self.layout.startswith(">") else "<"

    @property
    def codes(self) -> str:
        """One struct code per value of a scan."""
        body = self.layout.lstrip("<>")
        return "".join(int(n or 1) * c for n, c in re.findall(rf"(\d*)([{SAMPLE_CODES}])", body))

    @property
    def scan_dtype(self) -> np.dtype:
        return np.dtype([(f"v{i}", self.order + c) for i, c in enumerate(self.codes)])

    @property
    def wrap(self) -> int:
        return self.counter_wrap or (1 << (8 * self.counter_bytes))

    @property
    def length(self) -> int:
        return (len(self.header) + self.counter_bytes + self.scans * self.scan_dtype.itemsize
                + CHECKSUM_BYTES[self.checksum])


def encode_custom(spec: FrameSpec, first_frame: int, samples: np.ndarray) -> bytes:
    """Frames of ``spec`` for scans ``samples`` [n_frames * scans, n_values]; the first frame's number
    is ``first_frame`` (the counter field holds it, or its first sample's index, modulo the wrap)."""
    n_frames = samples.shape[0] // spec.scans
    scans = np.zeros(n_frames * spec.scans, spec.scan_dtype)
    for i, name in enumerate(spec.scan_dtype.names):
        scans[name] = samples[:, i]
    body = scans.view(np.uint8).reshape(n_frames, -1)
    if spec.counter_bytes:
        count = first_frame + np.arange(n_frames)
        count = (count * (spec.scans if spec.counter_counts == "samples" else 1)) % spec.wrap
        code = np.dtype(spec.order + COUNTER_CODES[spec.counter_bytes])
        body = np.concatenate([count.astype(code).view(np.uint8).reshape(n_frames, -1), body], axis=1)
    sums = [checksum(spec.checksum, row.tobytes()) for row in body] if spec.checksum != "none" else []
    k = CHECKSUM_BYTES[spec.checksum]
    tail = np.array(sums, spec.order + f"u{k}").view(np.uint8).reshape(n_frames, k) if k else \
        np.zeros((n_frames, 0), np.uint8)
    head = np.tile(np.frombuffer(spec.header, np.uint8), (n_frames, 1))
    return np.concatenate([head, body, tail], axis=1).tobytes()


def repair_counters(index: np.ndarray, step: int) -> tuple[np.ndarray, int]:
    """Sample indices of consecutive records with an isolated wrong counter put back in sequence.

    ``index[0]`` is the last trusted index before these records.  A record whose index does not follow
    its predecessor while its successor follows the predecessor by two steps had its counter corrupted
    (a flipped bit or digit that no checksum caught): it gets the index between its neighbours.
    Returns the indices and how many were repaired.
    """
    if index.size < 3:
        return index, 0
    d = np.diff(index)
    bad = (d[:-1] != step) & (index[2:] - index[:-2] == 2 * step)
    out = index.copy()
    out[1:-1][bad] = index[:-2][bad] + step
    return out, int(bad.sum())


class CustomDecoder:
    """Incremental decoder of the frames a :class:`FrameSpec` declares; same results as
    :meth:`BinaryDecoder.feed` (first sample index, values [n, n_values] float64, corrupt frames before).

    Candidate headers are found with numpy and checksums of all complete candidates computed at once
    (``sum8`` vectorised, CRCs one C call per frame); good frames are chained from the first one.
    Bytes belonging to no good frame count as ``ceil(bytes / frame length)`` corrupt frames.  Without a
    counter the frame number advances by one per good or corrupt frame; with one, the counter is
    unwrapped, isolated corrupted counters are repaired (:func:`repair_counters`), and a last frame not
    following its predecessor waits for the next read to be judged.
    """

    def __init__(self, spec: FrameSpec) -> None:
        self.spec = spec
        self.per = 1 if spec.counter_counts == "samples" else spec.scans  # samples per counter unit
        self.inc = spec.scans // self.per  # counter units per frame
        self._buf = b""
        self._joined = False
        self._garbage = 0
        self._unit: int | None = None  # counter (unwrapped; frame number without a counter) of the last frame
        self.repaired = 0

    def _good(self, arr: np.ndarray, starts: np.ndarray) -> np.ndarray:
        spec, n = self.spec, self.spec.length
        if spec.checksum == "none":
            return np.ones(starts.size, bool)
        frames = arr[starts[:, None] + np.arange(n)]
        k = CHECKSUM_BYTES[spec.checksum]
        body = frames[:, len(spec.header):n - k]
        stored = np.ascontiguousarray(frames[:, n - k:]).view(spec.order + f"u{k}")[:, 0]
        if spec.checksum == "sum8":
            return (body.sum(axis=1, dtype=np.int64) & 0xFF) == stored
        return np.array([checksum(spec.checksum, row.tobytes()) for row in body]) == stored

    def _units(self, arr: np.ndarray, starts: np.ndarray, corrupt: np.ndarray) -> np.ndarray:
        """Counter of each good frame, unwrapped and repaired (frame numbers without a counter)."""
        spec = self.spec
        if not spec.counter_bytes:
            return (-1 if self._unit is None else self._unit) + np.cumsum(corrupt + 1)
        hl = len(spec.header)
        code = np.dtype(spec.order + COUNTER_CODES[spec.counter_bytes])
        raw = np.ascontiguousarray(arr[starts[:, None] + np.arange(hl, hl + spec.counter_bytes)])
        raw = raw.view(code)[:, 0].astype(np.int64)
        prev = raw[0] if self._unit is None else self._unit
        step = (np.diff(np.r_[prev % spec.wrap, raw]) + spec.wrap // 2) % spec.wrap - spec.wrap // 2
        units = prev + np.cumsum(step)
        fixed, n = repair_counters(np.r_[prev, units], self.inc)
        self.repaired += n
        return fixed[1:]

    def feed(self, data: bytes) -> list[tuple[int, np.ndarray, int]]:
        spec, n, hl = self.spec, self.spec.length, len(self.spec.header)
        buf = self._buf + data
        arr = np.frombuffer(buf, np.uint8)
        if arr.size < hl:
            self._buf = buf
            return []
        head = np.frombuffer(spec.header, np.uint8)
        cand = np.flatnonzero(np.all([arr[i:arr.size - hl + 1 + i] == head[i] for i in range(hl)], axis=0))
        whole = cand[cand + n <= arr.size]
        good = self._good(arr, whole)
        chain, pos = [], 0
        for c, ok in zip(whole.tolist(), good.tolist(), strict=True):  # one step per candidate frame
            if ok and c >= pos:
                chain.append(c)
                pos = c + n
        starts = np.array(chain, np.int64)
        pending = cand[(cand + n > arr.size) & (cand >= pos)]
        cut = int(pending.min()) if pending.size else max(pos, arr.size - hl + 1)
        garbage = starts - np.r_[0, starts[:-1] + n]
        if starts.size:
            garbage[0] = garbage[0] + self._garbage if self._joined else 0
        corrupt = -(-garbage // n)
        units = self._units(arr, starts, corrupt)
        if spec.counter_bytes and starts.size:  # judge a last frame off the sequence with the next read
            before = units[-2] if starts.size > 1 else self._unit
            if before is not None and units[-1] - before != self.inc and corrupt[-1] == 0:
                cut = int(starts[-1])
                starts, corrupt, units = starts[:-1], corrupt[:-1], units[:-1]
        last_end = int(starts[-1]) + n if starts.size else 0
        cut = max(cut, last_end)
        self._buf = buf[cut:]
        if not starts.size:
            self._garbage += (cut - last_end) if self._joined else 0
            return []
        self._joined = True
        self._garbage = cut - last_end
        self._unit = int(units[-1])
        first = hl + spec.counter_bytes
        payload = np.ascontiguousarray(arr[starts[:, None] + np.arange(first, first + spec.scans
                                                                       * spec.scan_dtype.itemsize)])
        scans = payload.view(spec.scan_dtype).reshape(-1)
        values = np.column_stack([scans[name].astype(np.float64) for name in spec.scan_dtype.names])
        index = units * self.per
        split = np.flatnonzero((np.diff(index) != spec.scans) | (corrupt[1:] > 0)) + 1
        return [(int(index[a]), values[a * spec.scans:b * spec.scans], int(corrupt[a]))
                for a, b in zip(np.r_[0, split], np.r_[split, starts.size], strict=True)]
