"""Framing declared in the session TOML for real devices: custom binary frames (header, struct layout,
counter, checksum) and CSV lines with a checksum field; corrupted frames and counters against the exact
stream that was sent, through the decoders and end to end over a pty into the HDF5 run."""

from __future__ import annotations

import json

import numpy as np
import pytest
from stand_in import record_with, stream_paced

from flexmodal.daq.serial_frames import (
    CsvDecoder,
    CustomDecoder,
    FrameSpec,
    checksum,
    encode_csv,
    encode_custom,
)
from flexmodal.daq.session import load_session
from flexmodal.fixtures.sim_common import PtyLink

SPEC = FrameSpec(b"\xa5\x5a", "<12h", scans=1, counter_bytes=2, checksum="crc16")  # the acceptance frame


def test_checksum_known_answers():
    assert checksum("crc16", b"123456789") == 0x29B1  # CRC-16/CCITT-FALSE catalogue check value
    assert checksum("crc32", b"123456789") == 0xCBF43926  # CRC-32/ISO-HDLC (zlib)
    assert checksum("sum8", b"123456789") == sum(b"123456789") % 256 == 0xDD
    assert SPEC.length == 2 + 2 + 24 + 2


def _feed_in_pieces(decoder, data: bytes, rng, n_cuts: int = 300) -> dict[int, np.ndarray]:
    got = {}
    decoder.corrupt = 0
    cuts = np.r_[0, np.sort(rng.integers(0, len(data), n_cuts)), len(data)]
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        for first, values, n_bad in decoder.feed(data[a:b]):
            decoder.corrupt += n_bad
            got.update({first + i: row for i, row in enumerate(values)})
    return got


@pytest.mark.parametrize("spec", [
    SPEC,
    FrameSpec(b"\x7e", ">4h2f", scans=8, counter_bytes=1, counter_counts="samples", counter_wrap=200,
              checksum="sum8"),
    FrameSpec(b"\xaa\x55\x01", "<3i", scans=4, counter_bytes=4, checksum="crc32"),
    FrameSpec(b"\xa5\x5a", "<6H", scans=2, checksum="crc16"),  # no counter: frames are counted
])
def test_one_percent_corrupted_frames_all_detected_no_good_sample_lost(spec):
    rng = np.random.default_rng(3)
    n_frames = 20000
    x = rng.integers(0, 30000, (n_frames * spec.scans, len(spec.codes))).astype(float)  # fits every code
    first_frame = 250 if spec.counter_wrap != 200 else 10  # counters wrap during the stream
    raw = bytearray(encode_custom(spec, first_frame, x))
    bad = np.sort(rng.choice(np.arange(1, n_frames - 1), n_frames // 100, replace=False))
    for f in bad:  # one flipped bit anywhere in the frame: header, counter, samples or checksum
        raw[f * spec.length + int(rng.integers(0, spec.length))] ^= 1 << int(rng.integers(0, 8))
    decoder = CustomDecoder(spec)
    got = _feed_in_pieces(decoder, bytes(raw), rng)
    offset = first_frame * spec.scans if spec.counter_bytes else 0
    rows = {i - offset for i in got}
    lost = {f * spec.scans + k for f in bad for k in range(spec.scans)}
    assert rows == set(range(x.shape[0])) - lost  # every good sample, nothing else
    np.testing.assert_array_equal(np.array([got[i + offset] for i in sorted(rows)]),
                                  np.delete(x, sorted(lost), 0))
    assert decoder.corrupt == bad.size  # each corrupted frame detected and counted once


def test_corrupted_counter_without_checksum_blanks_no_good_data():
    spec = FrameSpec(b"\xa5\x5a", "<12h", counter_bytes=2)  # nothing protects the counter
    x = np.arange(5000 * 12, dtype=float).reshape(5000, 12) % 30000
    raw = bytearray(encode_custom(spec, 0, x))
    for f in (100, 2000, 4998):
        raw[f * spec.length + 3] ^= 0x40  # the counter's high byte: a jump of 16384 frames
    decoder = CustomDecoder(spec)
    got = _feed_in_pieces(decoder, bytes(raw), np.random.default_rng(0), 100)
    assert sorted(got) == list(range(5000)) and decoder.repaired == 3
    np.testing.assert_array_equal(np.array([got[i] for i in range(5000)]), x)


@pytest.mark.parametrize("kind", ["sum8", "crc16", "crc32"])
def test_csv_checksum_lines_and_corrupted_counters(kind):
    x = np.round(np.random.default_rng(5).normal(size=(3000, 3)) * 1000, 3)
    lines = encode_csv(0, x, kind).decode().splitlines(keepends=True)
    bad = list(range(50, 3000, 100))
    for i in bad:  # one wrong digit in the sequence number: the checksum catches it
        lines[i] = str(int(lines[i].split(",")[0]) + 9000) + lines[i][lines[i].index(","):]
    decoder = CsvDecoder(3, kind)
    got = _feed_in_pieces(decoder, "".join(lines).encode(), np.random.default_rng(1), 60)
    assert sorted(got) == sorted(set(range(3000)) - set(bad)) and decoder.corrupt == len(bad)
    np.testing.assert_array_equal(np.array([got[i] for i in sorted(got)]), np.delete(x, bad, 0))
    plain = encode_csv(0, x).decode().splitlines(keepends=True)
    for i in bad:  # without a checksum the same wrong digits are repaired from the neighbours
        plain[i] = str(int(plain[i].split(",")[0]) + 9000) + plain[i][plain[i].index(","):]
    decoder = CsvDecoder(3)
    got = _feed_in_pieces(decoder, "".join(plain).encode(), np.random.default_rng(1), 60)
    assert sorted(got) == list(range(3000)) and decoder.repaired == len(bad) and decoder.corrupt == 0


SESSION = """
sample_rate_hz = {rate}
[[device]]
name = "mcu"
protocol = "serial"
port = "{port}"
baud = 921600
sources = [{sources}]
{framing}
{channels}
"""
CUSTOM = """framing = "custom"
[device.frame]
header = [0xA5, 0x5A]
layout = "<12h"
counter_bytes = 2
checksum = "crc16"
"""


@pytest.mark.parametrize("framing", ["custom", "csv"])
def test_declared_framing_end_to_end_over_a_pty(tmp_path, framing):
    rate, n = 1000.0, 3000
    x = np.random.default_rng(9).integers(-30000, 30000, (n + 2000, 12)).astype(float)
    if framing == "custom":
        data = bytearray(encode_custom(SPEC, 0, x))
        for f in range(150, x.shape[0], 100):
            data[f * SPEC.length + 5] ^= 0x10  # a flipped bit in a sample
        records = [bytes(data[i:i + SPEC.length]) for i in range(0, len(data), SPEC.length)]
        declared = CUSTOM
    else:
        lines = encode_csv(0, x, "crc16").decode().splitlines(keepends=True)
        for f in range(150, x.shape[0], 100):
            lines[f] = "9" + lines[f]  # a wrong sequence number
        records, declared = [line.encode() for line in lines], 'framing = "csv"\nchecksum = "crc16"'
    link = PtyLink(tmp_path / "tty")
    names = [f"c{i}" for i in range(12)]
    channels = "".join(f'[[channel]]\nname = "{c}"\nkind = "voltage"\nunit = "count"\ndevice = "mcu"\n'
                       for c in names)
    config = tmp_path / "mcu.toml"
    config.write_text(SESSION.format(rate=rate, port=link.path, sources=", ".join(f'"{c}"' for c in names),
                                     framing=declared, channels=channels))
    try:
        device = lambda stop: stream_paced(link, lambda a, b: b"".join(records[a:b]), rate, stop, n + 2000)
        run = record_with(device, load_session(config), tmp_path / "run.h5", n / rate)
    finally:
        link.remove()
    first = int(next(iter(json.loads(run.attrs["first_index"]).values())))
    ref = x[first:first + n]
    bad = np.isnan(run.samples).any(axis=1)
    expected_bad = np.zeros(n, bool)
    expected_bad[[f - first for f in range(150, x.shape[0], 100) if 0 <= f - first < n]] = True
    np.testing.assert_array_equal(bad, expected_bad)  # exactly the corrupted records are missing
    np.testing.assert_array_equal(run.samples[~bad], ref[~bad])  # every good sample, exact
    corrupt = [e for e in run.events if e.kind == "corrupt"]
    assert sum(e.count for e in corrupt) == expected_bad.sum()
    assert not [e for e in run.events if e.kind == "gap"]
