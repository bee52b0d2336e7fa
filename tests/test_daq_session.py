"""Session config: the example sessions load; mistakes exit 2 with one line naming the item."""

from __future__ import annotations

from pathlib import Path

import pytest

from flexmodal.app import main
from flexmodal.daq.session import G_M_PER_S2, load_session, unit_factor

REPO = Path(__file__).resolve().parents[1]
SESSIONS = REPO / "examples" / "sessions"

BASE = """
sample_rate_hz = 1000.0
[[device]]
name = "adc"
protocol = "serial"
port = "loop://"
sources = ["c0", "c1"]
[[channel]]
name = "F"
kind = "force"
unit = "N"
device = "adc"
source = "c0"
sensitivity = 2.25
sensitivity_unit = "mV/N"
scale = 0.5
[[channel]]
name = "a1"
kind = "acceleration"
unit = "m/s^2"
device = "adc"
source = "c1"
sensitivity = 10.2
sensitivity_unit = "mV/g"
"""


@pytest.mark.parametrize("name", ["serial-sim", "can-sim", "modbus-sim"])
def test_example_sessions_load(name):
    s = load_session(SESSIONS / f"{name}.toml")
    assert s.simulator is not None and s.simulator.protocol == s.devices[0].protocol
    a1 = next(c for c in s.channels if c.channel.name == "a1")
    scale = 20000 / 65536 if name == "serial-sim" else 1.0  # mV per ADC count (DBC, registers: in mV)
    assert a1.gain() == pytest.approx(scale / 100.0 * G_M_PER_S2, rel=1e-12)


def test_conversion_chain(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(BASE)
    s = load_session(path)
    f, a = s.channels
    assert f.gain() == pytest.approx(0.5 / 2.25)  # mV per count / (mV/N) -> N per count
    assert a.gain() == pytest.approx(G_M_PER_S2 / 10.2)  # mV / (mV/g) * (m/s^2 per g)
    assert unit_factor("rev", "deg") == 360.0 and unit_factor("g", "furlong") is None


@pytest.mark.parametrize("edit,expected", [
    (('kind = "force"', 'kind = "forse"'), "channel 'F': kind = 'forse' is not one of acceleration"),
    (('sensitivity_unit = "mV/N"\n', ''), "channel 'F': sensitivity 2.25 has no sensitivity_unit"),
    (('device = "adc"\nsource = "c1"', 'device = "daq2"\nsource = "c1"'),
     "channel 'a1': device 'daq2' is not a device of this session"),
    (('port = "loop://"', 'port = "/dev/ttyNOPE7"'), "device 'adc': port '/dev/ttyNOPE7' does not exist"),
    (('source = "c0"', 'source = "c9"'), "channel 'F': source 'c9' is not one of device 'adc'"),
    (('sensitivity_unit = "mV/g"', 'sensitivity_unit = "mV/furlong"'), "cannot convert 'furlong'"),
    (('sample_rate_hz = 1000.0', 'sample_rate_hz = -5.0'), "sample_rate_hz = -5.0 must be in"),
    (('protocol = "serial"', 'protocol = "usb"'), "protocol = 'usb' is not one of serial, can, modbus"),
])
def test_config_mistakes_exit_2_with_one_line(tmp_path, capsys, edit, expected):
    path = tmp_path / "bad.toml"
    assert edit[0] in BASE
    path.write_text(BASE.replace(edit[0], edit[1], 1))
    code = main(["acquire", "--config", str(path), "--out", str(tmp_path / "r.h5"), "--duration", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and expected in err and str(path) in err
    assert not (tmp_path / "r.h5").exists()


def test_device_without_channels_is_an_error(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    spare = '[[device]]\nname = "spare"\nprotocol = "serial"\nport = "loop://"\nsources = ["x"]\n'
    path.write_text(BASE + spare)
    assert main(["acquire", "--config", str(path), "--out", str(tmp_path / "r.h5")]) == 2
    assert "device 'spare' has no channel mapped to it" in capsys.readouterr().err


SIM = BASE.replace('port = "loop://"', 'port = "@simulator"') + '[simulator]\nprotocol = "serial"\n'


@pytest.mark.parametrize("line,expected", [
    ('args = ["--link", "/etc/passwd"]', "simulator: unknown field 'args'"),
    ('fault_log = "/etc/passwd"', "fault_log = '/etc/passwd' must be a plain file name"),
    ('fault_log = "../escape.jsonl"', "fault_log = '../escape.jsonl' must be a plain file name"),
    ('corrupt_rate = 2.0', "corrupt_rate = 2.0 must be in [0, 1)"),
    ('effects = ["x@y:k=1 --link /tmp/z"]', "effects = ['x@y:k=1 --link /tmp/z'] must be a list of"),
    ('rig = "missing.toml"', "rig file"),
    ('link = "/tmp/x"', "simulator: unknown field 'link'"),
])
def test_simulator_block_takes_only_known_validated_options(tmp_path, capsys, line, expected):
    path = tmp_path / "sim.toml"
    path.write_text(SIM + line + "\n")
    assert main(["acquire", "--config", str(path), "--out", str(tmp_path / "r.h5"), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expected in err


def test_simulators_never_replace_or_append_to_other_files(tmp_path, capsys):
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me\n")
    for option in ("--link", "--fault-log"):
        code = main(["sim", "serve", "--protocol", "serial", "--duration", "0.1", option, str(victim)])
        assert code == 2 and str(victim) in capsys.readouterr().err
        assert victim.read_text() == "keep me\n"
