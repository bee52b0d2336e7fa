"""A reader reconnecting to a serial device never takes another device's bytes.

When a simulator's pty goes away (a simulated unplug) the kernel hands its number to the next pty
opened on the machine (another test's device stand-in, another simulator).  A reader retrying the
simulator's link used to open that pty and take part of its stream: the other run lost frames (gaps
of one frame each) and this one got foreign frames.  Now the link is gone while the device is away,
as a USB adapter's device node is, and the serial driver opens ports exclusively.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from flexmodal.daq.devices import Device, DeviceLost
from flexmodal.daq.serial_driver import SerialConfig, SerialDriver
from flexmodal.daq.serial_frames import encode_frames
from flexmodal.fixtures.sim_common import PtyLink

SOURCES = ("a", "b")


def _driver(path) -> SerialDriver:
    return SerialDriver(Device("adc", "serial", SerialConfig(str(path), SOURCES)), 1000.0)


def _read_all(driver: SerialDriver, n_samples: int, timeout_s: float = 60.0) -> np.ndarray:
    got, end = [], time.monotonic() + timeout_s
    while sum(b.values.shape[0] for b in got) < n_samples and time.monotonic() < end:
        got.extend(driver.read())
    return np.concatenate([b.values for b in got]) if got else np.zeros((0, len(SOURCES)))


def test_a_disconnected_link_cannot_reach_the_pty_that_reuses_its_number(tmp_path):
    link = PtyLink(tmp_path / "tty")
    link.close()   # the simulated unplug
    assert not os.path.lexists(link.path)
    other_master, other_slave = os.openpty()   # the next pty on the machine (here: the freed number)
    try:
        with pytest.raises(DeviceLost):
            _driver(link.path).open()
        link.open()   # the device is back: a new pty under the same path, and only that one is read
        counts = np.arange(64, dtype=float).reshape(32, 2)
        os.write(other_master, encode_frames(0, counts + 1000, 32, "int16"))
        link.write(encode_frames(0, counts, 32, "int16"))
        driver = _driver(link.path)
        driver.open()
        link.write(encode_frames(32, counts, 32, "int16"))   # after the open (which flushes the input)
        np.testing.assert_array_equal(_read_all(driver, 32), counts)
        driver.close()
    finally:
        os.close(other_master)
        os.close(other_slave)
        link.remove()
    assert not os.path.lexists(link.path)


def test_a_second_reader_of_an_open_port_does_not_open():
    link = PtyLink()
    first, second = _driver(link.path), _driver(link.path)
    try:
        first.open()
        with pytest.raises(DeviceLost, match="lock"):
            second.open()
        first.close()
        second.open()   # free again
        second.close()
    finally:
        link.remove()
