"""FRF estimators against pyFRF (same segments and window) and against an exact digital-filter FRF."""

from __future__ import annotations

import numpy as np
import pyFRF
import pytest
import scipy.signal

from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import coherence, convert, estimate, h1, h2, hv
from flexmodal.modal.spectra import welch_spectra

FS = 1024.0


def _two_mode_filter(fs: float) -> tuple[np.ndarray, np.ndarray]:
    """A stable digital filter with two lightly damped modes (bilinear transform of a 2-DOF system)."""
    poles = []
    for fn, zeta in ((40.0, 0.02), (110.0, 0.01)):
        wn = 2 * np.pi * fn
        poles += [complex(-zeta * wn, wn * np.sqrt(1 - zeta ** 2))]
    poles += [p.conjugate() for p in poles]
    z, p, k = scipy.signal.bilinear_zpk([-30.0, -200.0], poles, 1e4, fs)
    b, a = scipy.signal.zpk2tf(z, p, k)
    return b, a


@pytest.fixture(scope="module")
def random_test():
    """Random force through the filter, 40 dB SNR on the responses, 50 Hann segments with df << bandwidth."""
    rng = np.random.default_rng(1)
    b, a = _two_mode_filter(FS)
    nfft, n_avg = 8192, 50
    n = nfft * (n_avg + 1) // 2 + 4096
    force = rng.standard_normal(n)
    y = scipy.signal.lfilter(b, a, force)
    resp = np.column_stack([y, -0.5 * y])
    resp += 10 ** (-40 / 20) * np.std(resp, axis=0) * rng.standard_normal(resp.shape)
    samples = np.column_stack([force, resp])[4096:]
    return samples, b, a, nfft


def test_h1_matches_exact_frf_where_coherent(random_test):
    """Bias-free where coherence ~1 (1 % / 1 deg); elsewhere within 4 sigma of the H1 random error
    sqrt(1 - g2) / (|g| sqrt(2 n_avg)) (Bendat & Piersol 2010 §9.3), which is 2.3 % at g2 = 0.95."""
    samples, b, a, nfft = random_test
    s = welch_spectra(samples, FS, [0], [1, 2], nfft, window_spec="hann")
    assert s.n_averages >= 50
    H = h1(s)[:, 0]
    _, exact = scipy.signal.freqz(b, a, worN=s.freq_hz, fs=FS)
    ratio = H / np.stack([exact, -0.5 * exact])
    coh = coherence(s)
    mag_err, phase_err = np.abs(np.abs(ratio) - 1), np.abs(np.degrees(np.angle(ratio)))
    clean = coh > 0.999
    assert clean[:, (s.freq_hz > 10) & (s.freq_hz < 150)].mean() > 0.5
    assert mag_err[clean].max() < 0.01 and phase_err[clean].max() < 1.0
    ok = coh > 0.95
    sigma = np.sqrt(1 - coh[ok]) / (np.sqrt(coh[ok]) * np.sqrt(2 * s.n_averages))
    assert np.all(mag_err[ok] < 4 * sigma + 0.005)
    assert np.all(np.radians(phase_err[ok]) < 4 * sigma + 0.005)


@pytest.mark.parametrize("window", ["hann", "rect"])
def test_h1_h2_hv_coherence_agree_with_pyfrf(random_test, window):
    samples, _, _, nfft = random_test
    w = {"hann": np.hanning(nfft), "rect": np.ones(nfft)}[window]   # pyFRF's Hann is the symmetric one
    s = welch_spectra(samples, FS, [0], [1, 2], nfft, overlap=0.5, window_spec=w)
    ref = pyFRF.FRF(int(FS), exc=samples[:, 0][None, None, :], resp=samples[:, 1:].T[None],
                    exc_type="f", resp_type="d", window={"hann": "hann", "rect": "none"}[window],
                    nperseg=nfft, noverlap=nfft // 2, fft_len=nfft)
    lines = slice(1, None)   # pyFRF leaves 0 Hz undefined
    # Hv: pyFRF's (Gxx - Gff) + sqrt(...) cancels where Gxx << Gff; ours is the cancellation-free form
    for name, ours, tol in (("H1", h1(s), 1e-6), ("H2", h2(s), 1e-6), ("Hv", hv(s), 1e-4)):
        theirs = ref.get_FRF(frf_estimator=name, frf_form="receptance")
        rel = np.abs(ours[..., lines] - theirs[..., lines]) / np.abs(theirs[..., lines])
        assert rel.max() < tol, name
    assert np.allclose(coherence(s)[:, lines], ref.get_coherence()[:, lines], rtol=1e-6, atol=1e-9)


def test_float32_records_use_single_precision_and_stay_close(random_test):
    samples, _, _, nfft = random_test
    s64 = welch_spectra(samples, FS, [0], [1, 2], nfft)
    s32 = welch_spectra(samples.astype(np.float32), FS, [0], [1, 2], nfft)
    good = coherence(s64) > 0.95
    rel = np.abs(h1(s32) - h1(s64))[:, 0][good] / np.abs(h1(s64))[:, 0][good]
    assert rel.max() < 1e-4


@pytest.mark.parametrize("overlap", [0.5, 0.3])
def test_blocked_threaded_spectra_equal_scipy_csd_for_any_channel_order(overlap, monkeypatch):
    """Blocks of 5 segments (the last one short), two threads, piecewise segment means (50 %) or direct
    means (30 %), channels picked out of order: every spectrum equals scipy.signal.csd."""
    from flexmodal.modal import spectra as modal_spectra

    rng = np.random.default_rng(3)
    samples = rng.standard_normal((5000, 4)) + np.array([3.0, -1.0, 0.5, 2.0])   # offsets: detrend
    nfft, fs = 256, 100.0
    monkeypatch.setattr(modal_spectra, "_BLOCK_BYTES", 5 * 3 * nfft * 8)
    s1 = welch_spectra(samples, fs, [2], [3, 0], nfft, overlap=overlap, window_spec="hann")
    s2 = welch_spectra(samples, fs, [2], [3, 0], nfft, overlap=overlap, window_spec="hann", workers=2)
    noverlap = int(round(overlap * nfft))
    kw = dict(fs=fs, window=scipy.signal.get_window("hann", nfft), nperseg=nfft, noverlap=noverlap,
              detrend="constant")
    for k, o in enumerate([3, 0]):
        freq, gxf = scipy.signal.csd(samples[:, 2], samples[:, o], **kw)     # E[conj(F) X]
        _, gxx = scipy.signal.welch(samples[:, o], **kw)
        for s in (s1, s2):
            assert np.array_equal(s.freq_hz, freq)           # the same lines, to the last bit
            assert np.allclose(s.g_xf[k, 0], gxf, rtol=1e-10, atol=1e-12 * np.abs(gxf).max())
            assert np.allclose(s.g_xx[k], gxx, rtol=1e-10, atol=1e-12 * gxx.max())
    assert np.allclose(s1.g_ff[0, 0].real, scipy.signal.welch(samples[:, 2], **kw)[1], rtol=1e-10)


def test_multiple_references_recover_each_path():
    rng = np.random.default_rng(2)
    b, a = _two_mode_filter(FS)
    n = 2048 * 40
    f = rng.standard_normal((n, 2))
    y1 = scipy.signal.lfilter(b, a, f[:, 0]) + 0.3 * scipy.signal.lfilter(b, a, f[:, 1])
    samples = np.column_stack([f, y1])[4096:]
    s = welch_spectra(samples, FS, [0, 1], [2], 2048)
    H = h1(s)
    _, exact = scipy.signal.freqz(b, a, worN=s.freq_hz, fs=FS)
    band = coherence(s)[0] > 0.99
    assert band[(s.freq_hz > 20) & (s.freq_hz < 300)].mean() > 0.5
    assert np.allclose(H[0, 0, band], exact[band], rtol=0.02)
    assert np.allclose(H[0, 1, band], 0.3 * exact[band], rtol=0.05)   # the weaker path: larger random error
    with pytest.raises(ModalError, match="single reference"):
        h2(s)


def test_conversions_are_powers_of_i_omega():
    freq = np.array([0.0, 1.0, 10.0])
    rec = np.array([1.0 + 1j, 2.0, 3.0j])
    acc = convert(rec, freq, "receptance", "accelerance")
    assert np.allclose(acc[1:], rec[1:] * (2j * np.pi * freq[1:]) ** 2)
    assert np.allclose(convert(acc, freq, "accelerance", "receptance")[1:], rec[1:])
    assert np.isnan(convert(acc, freq, "accelerance", "mobility")[0])
    with pytest.raises(ModalError, match="estimator"):
        estimate(welch_spectra(np.ones((64, 2)) + np.arange(64)[:, None], FS, [0], [1], 16), "H3")


@pytest.mark.parametrize("name", ["hann", "flattop"])
def test_windows_equal_scipy_periodic_windows(name):
    from flexmodal.modal.windows import window

    for n in (8, 255, 4096):
        reference = scipy.signal.get_window(name, n, fftbins=True)
        assert np.allclose(window(name, n), reference, rtol=0, atol=1e-14)


def test_tiny_segments_with_many_outputs_equal_scipy_csd():
    """nfft 8 and 11 outputs: the products of a block need more memory than its windowed segments
    (whose buffer they reuse); every cross- and auto-spectrum still equals scipy.signal.csd."""
    x = np.random.default_rng(0).standard_normal((400, 12))
    s = welch_spectra(x, 10.0, [0], list(range(1, 12)), 8)
    kw = dict(fs=10.0, window="hann", nperseg=8, noverlap=4)
    for k in range(11):
        _, gxf = scipy.signal.csd(x[:, 0], x[:, k + 1], **kw)
        assert np.allclose(s.g_xf[k, 0], gxf, rtol=1e-10, atol=1e-14)
        assert np.allclose(s.g_xx[k], scipy.signal.welch(x[:, k + 1], **kw)[1], rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("window", ["hann", "flattop"])
def test_float32_record_with_a_large_offset_keeps_single_precision_accuracy(window):
    """A float32 record riding on offsets up to 2e4 times its fluctuation (a biased force sensor):
    the spectra equal scipy.signal.csd of the same stored samples in double precision to 2e-6 on every
    line but the two the mean removal sets (the offset is taken out before the single-precision FFT;
    removing a single-precision mean of 2e4 after the fact left 4e-3 through the flat-top's lines)."""
    rng = np.random.default_rng(5)
    x32 = (rng.standard_normal((200_000, 3)) + np.array([2e4, -50.0, 1e3])).astype(np.float32)
    s = welch_spectra(x32, 100.0, [0], [1, 2], 1024, window_spec=window)
    kw = dict(fs=100.0, window=scipy.signal.get_window(window, 1024), nperseg=1024, noverlap=512,
              detrend="constant")
    x = x32.astype(float)
    segments = np.lib.stride_tricks.sliding_window_view(x, 1024, axis=0)[::512]   # [seg, ch, 1024]
    assert np.allclose(s.mean, segments.mean(axis=(0, 2)), rtol=1e-10, atol=0)   # mean of segment means
    for k in (1, 2):
        _, gxf = scipy.signal.csd(x[:, 0], x[:, k], **kw)
        _, gxx = scipy.signal.welch(x[:, k], **kw)
        assert np.max(np.abs(s.g_xf[k - 1, 0, 2:] - gxf[2:])) <= 2e-6 * np.abs(gxf[2:]).max()
        assert np.max(np.abs(s.g_xx[k - 1, 2:] / gxx[2:] - 1)) <= 2e-6


def test_float32_record_frfs_equal_double_precision_scipy_to_single_precision_rounding(random_test):
    """The one pass on float32 samples (strided windowing, single-precision FFT, the means taken out
    of the first lines, batched products) against scipy's double-precision Welch of the same stored
    samples: on every line where the coherence exceeds 0.5, H1 and H2 within 1e-5 relative and the
    coherence within 1e-5 (the engine it replaced differed from this one on the demo's FRF groups by
    2.2e-6 of the largest |H| and 1.4e-5 in coherence)."""
    samples, _, _, nfft = random_test
    x32 = (samples + np.array([0.3, -0.2, 0.1])).astype(np.float32)    # offsets within the spread
    s = welch_spectra(x32, FS, [0], [1, 2], nfft)
    x = x32.astype(float)
    kw = dict(fs=FS, window="hann", nperseg=nfft, noverlap=nfft // 2, detrend="constant")
    _, gff = scipy.signal.welch(x[:, 0], **kw)
    for k in (1, 2):
        _, gxf = scipy.signal.csd(x[:, 0], x[:, k], **kw)
        _, gxx = scipy.signal.welch(x[:, k], **kw)
        ref_h1, ref_h2, ref_c = gxf / gff, gxx / gxf.conj(), np.abs(gxf) ** 2 / (gff * gxx)
        good = ref_c > 0.5
        for ours, ref in ((h1(s)[k - 1, 0], ref_h1), (h2(s)[k - 1, 0], ref_h2)):
            assert np.max(np.abs(ours - ref)[good] / np.abs(ref)[good]) <= 1e-5
        assert np.max(np.abs(coherence(s)[k - 1] - ref_c)[good]) <= 1e-5


def test_any_window_array_and_an_unused_column_between_the_used_ones():
    """A window given as samples (symmetric Hann: its spectrum is not a few lines, so each segment's
    mean leaves before windowing) on a record with offsets, the force in the last column and an
    unused column of NaN between the used ones (an encoder that dropped out): every spectrum equals
    scipy.signal.csd, and no segment is left out for the unused column."""
    rng = np.random.default_rng(7)
    x = rng.standard_normal((6000, 4)) + np.array([5.0, np.nan, -2.0, 1.0])
    x[:, 1] = np.nan
    w = np.hanning(512)
    s = welch_spectra(x, 100.0, [3], [0, 2], 512, window_spec=w)
    assert s.n_skipped == 0
    kw = dict(fs=100.0, window=w, nperseg=512, noverlap=256, detrend="constant")
    for k, o in enumerate([0, 2]):
        _, gxf = scipy.signal.csd(x[:, 3], x[:, o], **kw)
        _, gxx = scipy.signal.welch(x[:, o], **kw)
        assert np.allclose(s.g_xf[k, 0], gxf, rtol=1e-10, atol=1e-12 * np.abs(gxf).max())
        assert np.allclose(s.g_xx[k], gxx, rtol=1e-10, atol=1e-12 * gxx.max())
