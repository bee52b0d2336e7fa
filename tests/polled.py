"""Checks of a run polled from the Modbus simulator (its column 0 is the device's sample counter) that hold
on a loaded machine too.

The simulator runs as a logger with a FIFO (``modbus_fifo_s``) and the sessions name its counter
register, so each answer is stored at the sample its counter names (daq/modbus_driver.py).  A poller
starved of CPU longer than the FIFO holds loses samples (the device drops them; a device silent for the
answer timeout is reconnected).
Then exactly the rows missed are NaN, each reported as a gap event, and every other row is the emitted
sample of that row: that is what these checks demand.
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
    [n, columns - 1] physical values from sample 0) and that counter is its row (the first sample is row
    0), the missing rows are reported gaps and nothing is corrupt; on a quiet machine (no row missing)
    there is no gap and no reconnect."""
    assert run.samples.shape[0] == n
    good = assert_missing_rows_are_reported_gaps(run.samples, [(e.sample_index, e.count) for e in run.events
                                                               if e.kind == "gap"])
    counter, rows = run.samples[good, 0].astype(int), np.flatnonzero(good)
    np.testing.assert_array_equal(counter, rows)
    assert (np.abs(run.samples[good, 1:] - expected[counter]) / steps).max() <= 1.0
    assert not [e for e in run.events if e.kind == "corrupt"]
    if good.all():  # a quiet machine: not one poll missed, no reconnect
        assert not [e for e in run.events if e.kind in ("gap", "reconnect")]
