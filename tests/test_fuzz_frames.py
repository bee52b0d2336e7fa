"""Fuzz the serial stream decoders and the DBC signal decoder: no input raises, none hangs, and good
frames inside garbage decode to exactly the samples that were encoded."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO
from fuzz_support import LONG_EXAMPLES, prop, run_profile
from hypothesis import strategies as st

from flexmodal.daq.dbc import load_message
from flexmodal.daq.errors import DaqError
from flexmodal.daq.serial_frames import BinaryDecoder, CsvDecoder, encode_csv, encode_frames

N_CH = 3
FRAME_BYTES_LONG = 100_000  # inputs of the mutation run of the long profile


def _check_runs(runs: list, n_ch: int) -> None:
    for seq, values, corrupt in runs:
        assert isinstance(seq, int) and seq >= 0
        assert isinstance(corrupt, int) and corrupt >= 0
        assert values.ndim == 2 and values.shape[1] == n_ch and values.shape[0] >= 1


@st.composite
def framed_stream(draw) -> tuple[bytes, np.ndarray, list[int]]:
    """Garbage, then good frames of random int16 samples, then garbage, cut at random points."""
    n_frames = draw(st.integers(1, 6))
    scans = draw(st.integers(1, 16))
    fmt = draw(st.sampled_from(["int16", "int32", "float32"]))
    seed = draw(st.integers(0, 2**31))
    values = np.random.default_rng(seed).integers(-30000, 30000, (n_frames * scans, N_CH)).astype(float)
    junk = draw(st.binary(max_size=64)).replace(b"\xa5", b"\x00")
    tail = draw(st.binary(max_size=64)).replace(b"\xa5", b"\x00")
    data = junk + encode_frames(7, values, scans, fmt) + tail
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=6)))
    return data, values, cuts


@prop(framed_stream())
def prop_binary_known_answer(case) -> None:
    data, values, cuts = case
    decoder = BinaryDecoder(N_CH)
    runs = []
    for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True):
        runs += decoder.feed(data[a:b])
    _check_runs(runs, N_CH)
    got = np.concatenate([r[1] for r in runs]) if runs else np.empty((0, N_CH))
    np.testing.assert_array_equal(got, values)
    assert runs[0][0] == 7


@prop(st.lists(st.binary(max_size=200), max_size=5), st.integers(1, 8))
def prop_binary_garbage(chunks: list[bytes], n_ch: int) -> None:
    decoder = BinaryDecoder(n_ch)
    for chunk in chunks:
        _check_runs(decoder.feed(chunk), n_ch)


@prop(st.lists(st.binary(max_size=120) | st.text(alphabet="0123456789,.-e\r\nnaif ", max_size=120).map(
    str.encode), max_size=5), st.integers(1, 5))
def prop_csv_garbage(chunks: list[bytes], n_ch: int) -> None:
    decoder = CsvDecoder(n_ch)
    for chunk in chunks:
        _check_runs(decoder.feed(chunk), n_ch)


@prop(st.integers(0, 2**31), st.integers(1, 40))
def prop_csv_known_answer(seed: int, n: int) -> None:
    values = np.round(np.random.default_rng(seed).normal(size=(n, N_CH)), 6)
    runs = CsvDecoder(N_CH).feed(b"partial\n" + encode_csv(3, values))
    np.testing.assert_allclose(np.concatenate([r[1] for r in runs]), values, rtol=1e-12)
    assert runs[0][0] == 3


DBC = REPO / "fixtures" / "flexmodal_sim.dbc"


@prop(st.binary(min_size=0, max_size=8 * 40))
def prop_dbc_decode(raw: bytes) -> None:
    layout = load_message(str(DBC))
    n = len(raw) // 8
    frames = np.frombuffer(raw[:n * 8], np.uint8).reshape(n, 8)
    for sig in layout.signals:
        value = layout.decode(frames, sig)
        assert value.shape == (n,)
        lo, hi = sig.limits
        finite = value[np.isfinite(value)]
        assert np.all((finite >= lo - 1e-9 * abs(lo)) & (finite <= hi + 1e-9 * abs(hi)))


@prop(st.integers(0, 4000), st.text(st.characters(blacklist_categories=("Cs",)), max_size=200))
def prop_dbc_text(keep: int, text: str) -> None:
    """The sample DBC cut after ``keep`` characters with random text appended."""
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "x.dbc"
        path.write_text(DBC.read_text()[:keep] + text)
        try:
            load_message(str(path))
        except DaqError:
            pass


def test_binary_frames_known_answer() -> None:
    run_profile(prop_binary_known_answer, 100)


def test_binary_frames_garbage() -> None:
    run_profile(prop_binary_garbage, 100)


def test_csv_lines() -> None:
    run_profile(prop_csv_garbage, 150)
    run_profile(prop_csv_known_answer, 50)


def test_dbc() -> None:
    run_profile(prop_dbc_decode, 50)
    run_profile(prop_dbc_text, 20)


def mutated_frames(n_inputs: int, seed: int = 0):
    """``n_inputs`` byte strings: valid frame streams with random bytes overwritten, dropped or inserted."""
    rng = np.random.default_rng(seed)
    base = encode_frames(0, rng.integers(-999, 999, (64, N_CH)).astype(float), 8, "int16")
    arr = np.frombuffer(base, np.uint8)
    for _ in range(n_inputs):
        x = arr.copy()
        k = int(rng.integers(1, 12))
        x[rng.integers(0, x.size, k)] = rng.integers(0, 256, k)
        cut = np.sort(rng.integers(0, x.size, 2))
        if rng.random() < 0.5:
            x = np.delete(x, np.arange(cut[0], cut[1]))
        yield x.tobytes()


def test_binary_frames_mutations_bounded() -> None:
    decoder = BinaryDecoder(N_CH)
    for data in mutated_frames(1000):
        _check_runs(decoder.feed(data), N_CH)


@pytest.mark.slow
def test_long_binary_frames() -> None:
    """Long profile: 10^5 mutated streams through one decoder, then the hypothesis properties."""
    decoder = BinaryDecoder(N_CH)
    n = 0
    for data in mutated_frames(FRAME_BYTES_LONG, seed=1):
        _check_runs(decoder.feed(data), N_CH)
        n += 1
    assert n == FRAME_BYTES_LONG
    run_profile(prop_binary_known_answer, LONG_EXAMPLES, long=True)
    run_profile(prop_binary_garbage, LONG_EXAMPLES, long=True)


@pytest.mark.slow
def test_long_csv_and_dbc() -> None:
    run_profile(prop_csv_garbage, LONG_EXAMPLES, long=True)
    run_profile(prop_csv_known_answer, LONG_EXAMPLES, long=True)
    run_profile(prop_dbc_decode, LONG_EXAMPLES, long=True)
    run_profile(prop_dbc_text, LONG_EXAMPLES, long=True)
