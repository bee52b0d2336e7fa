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

import numpy as np

SYNC = b"\xa5\x5a"
HEADER_BYTES = 10
CRC_BYTES = 2
FORMATS = {1: np.dtype("<i2"), 2: np.dtype("<i4"), 3: np.dtype("<f4")}
FORMAT_CODES = {"int16": 1, "int32": 2, "float32": 3}
SEQ_MODULUS = 2**32
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
    header["sync"] = 0x5AA5
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
        starts = np.flatnonzero((arr[:-1] == 0xA5) & (arr[1:] == 0x5A))
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
        cut = int(pending.min()) if pending.size else arr.size - int(arr[-1] == 0xA5)
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
    """Incremental decoder of CSV lines ``seq,v1,..,v_n`` for ``n_ch`` channels."""

    def __init__(self, n_ch: int) -> None:
        self.n_ch = n_ch
        self._buf = b""
        self._garbage = 0
        self._joined = False  # the first (maybe partial) line after opening is not counted as corrupt

    def feed(self, data: bytes) -> list[tuple[int, np.ndarray, int]]:
        """Same result as :meth:`BinaryDecoder.feed`; a bad line counts as one corrupt frame."""
        buf = self._buf + data
        cut = buf.rfind(b"\n") + 1
        self._buf = buf[cut:]
        lines = buf[:cut].split(b"\n")[:-1]
        if not lines:
            return []
        fields = [line.split(b",") for line in lines]
        shape_ok = np.array([len(f) == self.n_ch + 1 for f in fields])
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
        gi = np.flatnonzero(good)
        counted = ~good
        if not self._joined:  # lines before the first good one: the partial line we joined in
            counted[:np.argmax(good) if good.any() else good.size] = False
            self._joined = bool(good.any())
        bad_before = np.cumsum(counted) + self._garbage
        seq = table[gi, 0].astype(np.int64)
        n_bad = np.diff(np.concatenate([[0], bad_before[gi]]))
        split = np.flatnonzero((np.diff(seq) != 1) | (n_bad[1:] > 0)) + 1
        runs = [(int(seq[a]), table[gi[a:b], 1:], int(n_bad[a]))
                for a, b in zip(np.r_[0, split], np.r_[split, gi.size], strict=True) if b > a]
        self._garbage = int(bad_before[-1] - (bad_before[gi[-1]] if gi.size else 0)) if self._joined else 0
        return runs


def encode_csv(first_seq: int, values: np.ndarray) -> bytes:
    """CSV lines for scans ``values`` [n, n_ch] starting at sample index ``first_seq``."""
    seq = np.arange(first_seq, first_seq + values.shape[0])
    table = np.column_stack([seq, values])
    return "".join(",".join(f"{v:.10g}" for v in row) + "\n" for row in table).encode()
