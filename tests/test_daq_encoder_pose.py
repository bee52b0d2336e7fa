"""Encoder channels: counts -> degrees by a declared resolution, and the run's pose taken from them (mean
and spread stored), streamed over a pty and then used by `flexmodal identify` for the pose columns."""

from __future__ import annotations

import json
import threading

import numpy as np
import pandas as pd
from stand_in import record_with, stream_paced

from flexmodal.app import main
from flexmodal.daq.serial_frames import encode_csv
from flexmodal.daq.session import load_session
from flexmodal.fixtures.sim_common import PtyLink
from flexmodal.fixtures.sim_source import sim_source

RATE = 2048.0
COUNTS_PER_REV = 4096


def _encoder(k: np.ndarray) -> np.ndarray:
    """Elbow encoder counts: 45 deg (512 counts) with a slow wobble of +-2 counts."""
    return 512 + (k // 700) % 5 - 2


def _device(link: PtyLink, stop: threading.Event) -> None:
    """The stand-in MCU: CSV lines of the simulated impact test plus the encoder, paced in real time."""
    src = sim_source(None, "impact", RATE)
    stream_paced(link, lambda a, b: encode_csv(a, np.column_stack([src.block(a, b - a),
                                                                       _encoder(np.arange(a, b))])),
                     RATE, stop)


def test_pose_from_encoder_mean_and_spread_reach_identify(tmp_path):
    src = sim_source(None, "impact", RATE)
    link = PtyLink(tmp_path / "tty")
    sources = [f"ch{i}" for i in range(len(src.channels))] + ["enc"]
    chans = "".join(f'[[channel]]\nname = "{c.name}"\nkind = "{c.kind}"\nunit = "{c.unit}"\ndevice = "mcu"\n'
                    f'source = "ch{i}"\nscale = {c.scale!r}\nsensitivity = {c.sensitivity!r}\n'
                    f'sensitivity_unit = "{c.sensitivity_unit}"\nlocation = "{c.location}"\n'
                    for i, c in enumerate(src.channels))
    chans += (f'[[channel]]\nname = "enc_elbow"\nkind = "encoder"\nunit = "deg"\ndevice = "mcu"\n'
              f'source = "enc"\ncounts_per_rev = {COUNTS_PER_REV}\n')
    config = tmp_path / "enc.toml"
    config.write_text(f'sample_rate_hz = {RATE}\nexcitation = "impact"\npose = {{ payload_kg = 0.5 }}\n'
                      f'pose_from = {{ theta_deg = "enc_elbow" }}\n[[device]]\nname = "mcu"\n'
                      f'protocol = "serial"\nport = "{link.path}"\nframing = "csv"\n'
                      f'sources = {json.dumps(sources)}\n{chans}')
    try:
        run = record_with(lambda stop: _device(link, stop), load_session(config), tmp_path / "run.h5", 4.5)
    finally:
        link.remove()
    first = json.loads(run.attrs["first_index"])["mcu"]
    angle = _encoder(first + np.arange(run.samples.shape[0])) * 360.0 / COUNTS_PER_REV
    # every row is its own sample: no gap (NaN rows seen in CI at load 10-14 were a line cut inside its
    # counter when the starved acquisition opened the port mid-stream, read as a sample: daq/serial_frames)
    assert not np.isnan(run.samples).any() and not [e for e in run.events if e.kind in ("gap", "corrupt")]
    np.testing.assert_allclose(run.samples[:, -1], angle, rtol=0, atol=1e-9)  # counts -> deg
    assert angle.std() > 0.05  # the wobble: a mean, not one sample
    assert run.pose.keys() == {"payload_kg", "theta_deg"} and run.pose["payload_kg"] == 0.5
    assert abs(run.pose["theta_deg"] - angle.mean()) < 1e-9
    spread = json.loads(run.attrs["pose_spread"])["theta_deg"]
    assert abs(spread["std"] - angle.std()) < 1e-9 and spread["n"] == angle.size
    assert (spread["min"], spread["max"]) == (angle.min(), angle.max())
    out = tmp_path / "modes.csv"
    assert main(["--quiet", "identify", str(tmp_path / "run.h5"), "--out", str(out), "--method", "peak",
                 "--fmax", "200"]) == 0
    table = pd.read_csv(out)
    assert np.allclose(table["pose.theta_deg"], run.pose["theta_deg"], rtol=1e-6, atol=0)  # CSV digits
    assert (table["pose.payload_kg"] == 0.5).all()
