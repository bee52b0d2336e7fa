"""Checks of a run polled from the Modbus simulator (its column 0 is the device's sample counter) that hold
on a loaded machine too.

On a quiet machine every poll gets the next sample.  A poller (or the simulator) starved of CPU misses
polls (daq/modbus_driver.py: a poll later than MAX_LATE_S is skipped, a device silent for its answer
timeout is reconnected): seen at load 28.  Then exactly the rows missed are NaN, each reported as a gap
event, and every other row is still an emitted sample, in order: that is what these checks demand.
"""

from __future__ import annotations

import numpy as np


def assert_missing_rows_are_reported_gaps(samples: np.ndarray, gaps: list[tuple[int, int]]) -> np.ndarray:
    """Rows of ``samples`` with any NaN are exactly the rows of the gap events ``gaps`` ((first row,
    count) each), and those rows are NaN throughout; returns the mask of the good rows."""
    missed = np.zeros(samples.shape[0], bool)
    for first, count in gaps:
        missed[first:first + count] = True
    np.testing.assert_array_equal(np.isnan(samples).any(axis=1), missed)
    assert np.isnan(samples[missed]).all()
    return ~missed


def assert_polled(run, n: int, expected: np.ndarray, steps: np.ndarray) -> None:
    """``run`` holds ``n`` rows of polls: each good row holds the emitted sample its counter (column 0)
    names (the other columns within one quantisation step ``steps`` of ``expected[counter]``; ``expected``
    [n, columns - 1] physical values from sample 0), consecutive good rows consecutive samples, the
    missing rows are reported gaps and nothing is corrupt; on a quiet machine (no row missing) the
    counter is the row, and there is no gap and no reconnect.  (The device samples on demand: across a
    gap its counter goes on from where it was, seen with the simulator frozen 2.5 s.)"""
    assert run.samples.shape[0] == n
    good = assert_missing_rows_are_reported_gaps(run.samples, [(e.sample_index, e.count) for e in run.events
                                                               if e.kind == "gap"])
    counter, rows = run.samples[good, 0].astype(int), np.flatnonzero(good)
    assert (np.diff(counter) >= 1).all() and (np.diff(counter)[np.diff(rows) == 1] == 1).all()
    assert (np.abs(run.samples[good, 1:] - expected[counter]) / steps).max() <= 1.0
    assert not [e for e in run.events if e.kind == "corrupt"]
    if good.all():  # a quiet machine: not one poll missed, no reconnect
        np.testing.assert_array_equal(counter, np.arange(n))
        assert not [e for e in run.events if e.kind in ("gap", "reconnect")]
