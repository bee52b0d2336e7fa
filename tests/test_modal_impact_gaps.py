"""Runs with imperfect records (issue 12 point 6): an impact hit whose record overlaps lost frames
(NaN rows with a corrupt event, as the acquisition stores them) and a last hit cut short by the end of
the data are rejected one by one with the reason; the other hits give the same FRFs as those hits
alone, and the modes of the model.  A random run with 1 % lost frames identifies like the clean run."""

from __future__ import annotations

import numpy as np
from modal_cases import four_mode_random_record

from flexmodal.daq.store import Channel, Event, RunWriter, read_run
from flexmodal.fixtures.modal_sim import modal_response
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.frf import estimate
from flexmodal.modal.identify import identify
from flexmodal.modal.impact import impact_spectra

FS = 512.0
FN, ZETA = np.array([20.0, 47.0, 90.0]), np.array([0.02, 0.015, 0.01])
PHI = np.array([[1.0, 0.7, 0.4], [0.6, -0.8, 0.9]])
PERIOD = 4 * int(FS)                  # a hit every 4 s
PRE = int(round(0.02 * FS))


def _hits(n_hits: int, tail_s: float) -> tuple[np.ndarray, list[int]]:
    """Force and two accelerations: ``n_hits`` hits, the data ending ``tail_s`` after the last one."""
    n = (n_hits - 1) * PERIOD + 200 + int(tail_s * FS)
    force = np.zeros((n, 1))
    pulse = np.sin(np.pi * np.arange(6) / 5)
    trig = [k * PERIOD + 200 for k in range(n_hits)]
    for k, t in enumerate(trig):
        force[t:t + 6, 0] = (80 + 5 * k) * pulse
    y = modal_response(force, FS, FN, ZETA, PHI, PHI[[0]])
    y += 1e-4 * np.abs(y).max() * np.random.default_rng(1).standard_normal(y.shape)
    return np.column_stack([force, y]), trig


def test_a_gap_through_one_hit_and_a_short_last_hit_are_rejected_alone(tmp_path):
    samples, trig = _hits(5, tail_s=0.25)
    lost = slice(trig[1] + 700, trig[1] + 760)               # 60 lost samples in the 2nd hit's decay
    samples[lost] = np.nan
    path = tmp_path / "impact.h5"
    channels = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2"),
                Channel("a2", "acceleration", "m/s^2")]
    with RunWriter(path, "hits", sample_rate_hz=FS, channels=channels, excitation="impact",
                   pose={}) as w:
        w.append(samples)
        w.add_events([Event("corrupt", lost.start, lost.stop - lost.start, "bad CRC")])
    run = read_run(path, "hits")
    res = compute_frf(run)
    hits = res.provenance["hits"]
    assert [h["accepted"] for h in hits] == [True, False, True, True, False]
    assert hits[1]["reason"].startswith("gap: lost data at samples")
    assert hits[4]["reason"] == "truncated: the data end 0.248 s after the trigger, the record needs 3.98 s"
    assert res.n_averages == 3
    # known answer: exactly the FRFs of the three good hits processed on their own
    alone, _ = impact_spectra(np.nan_to_num(run.samples), FS, 0, [1, 2], record_len=PERIOD,
                              triggers=[hits[k]["trigger"] for k in (0, 2, 3)])
    # (equal_nan: the pulse has no energy at the Nyquist line, 0/0 there in both)
    assert np.allclose(res.H, estimate(alone, "H1"), rtol=1e-10, atol=0, equal_nan=True)
    modes = identify(res.freq_hz, res.H, fmin=5, fmax=150, decay_rate_per_s=res.decay_rate_per_s)
    assert np.allclose(modes.freq_hz, FN, rtol=1e-3)
    assert np.allclose(modes.damping_ratio, ZETA, rtol=0.05)


def test_nan_rows_without_an_event_reject_the_hit_that_holds_them():
    samples, trig = _hits(4, tail_s=4.0)
    samples[trig[2] + 50] = np.nan
    _, hits = impact_spectra(samples, FS, 0, [1, 2])
    assert [h.accepted for h in hits] == [True, True, False, True]
    offset = (trig[2] + 50 - hits[2].start) / FS
    assert hits[2].reason == (f"gap: 1 non-finite samples from sample {trig[2] + 50} "
                              f"({offset:.3g} s into the record)")


def test_a_last_hit_nearly_complete_still_sets_a_slightly_shorter_record_for_all():
    samples, trig = _hits(3, tail_s=3.9)                   # the last record holds 97 % of the period
    spectra, hits = impact_spectra(samples, FS, 0, [1, 2])
    assert all(h.accepted for h in hits) and spectra.n_averages == 3
    assert spectra.freq_hz.size == (samples.shape[0] - hits[2].start) // 2 + 1 < PERIOD // 2


def test_a_random_run_with_one_percent_lost_frames_identifies_like_the_clean_run(tmp_path):
    """1 % of 32-sample frames lost (NaN rows with corrupt events, as the acquisition stores them):
    the Welch segments touching them are skipped (modal.spectra) and the modes stay within 0.1 % of
    the clean run's."""
    fs, frame = 1024.0, 32
    rng = np.random.default_rng(3)
    clean = four_mode_random_record(rng, fs)
    lost = np.flatnonzero(rng.random(clean.shape[0] // frame) < 0.01)
    gappy = clean.copy()
    gappy[(lost[:, None] * frame + np.arange(frame)).ravel()] = np.nan
    channels = [Channel("F", "force", "N")] + [Channel(f"a{k}", "acceleration", "m/s^2") for k in (1, 2, 3)]
    path = tmp_path / "random.h5"
    corrupt = [Event("corrupt", int(b * frame), frame) for b in lost]
    for run_id, samples, events in (("clean", clean, []), ("gappy", gappy, corrupt)):
        with RunWriter(path, run_id, sample_rate_hz=fs, channels=channels, excitation="random", pose={}) as w:
            w.append(samples)
            w.add_events(events)
    res = {r: compute_frf(read_run(path, r), nfft=2048) for r in ("clean", "gappy")}
    assert res["gappy"].provenance["segments_skipped"] > 0
    modes = {r: identify(x.freq_hz, x.H, fmin=10, fmax=400) for r, x in res.items()}
    assert modes["clean"].freq_hz.size == modes["gappy"].freq_hz.size == 4
    assert np.all(np.abs(modes["gappy"].freq_hz / modes["clean"].freq_hz - 1) < 1e-3)
