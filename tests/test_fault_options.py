"""The simulator's fault options are defined once (daq.faults.Faults): a session's [simulator] keys,
``sim serve``'s options and the command line the launcher builds all follow its fields, so a fault set in
a session reaches the simulator process unchanged."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from flexmodal.app import build_parser
from flexmodal.daq.faults import Faults, fault_flag
from flexmodal.daq.session import load_session
from flexmodal.fixtures import sim_serve

REPO = Path(__file__).resolve().parents[1]
CHOSEN = {"corrupt_rate": 0.01, "drop_at_s": 1.5, "drop_s": 0.3, "disconnect_after_s": 2.0,
          "disconnect_s": 0.25, "double_hit_at_s": 2.1, "overload_at_s": 4.1,
          "overrun_after_s": 30.0, "modbus_fifo_s": 2.5}


def test_the_fields_are_the_session_keys_and_the_sim_serve_options(tmp_path, monkeypatch):
    assert {f.name for f in fields(Faults)} == set(CHOSEN)
    text = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text()
    text = text.replace("[simulator]\n", "[simulator]\n" + "".join(f"{k} = {v}\n" for k, v in CHOSEN.items()))
    rig = REPO / "examples" / "rigs" / "demo_arm.toml"
    text = text.replace('rig = "../rigs/demo_arm.toml"', f'rig = "{rig}"')
    (tmp_path / "s.toml").write_text(text)
    session = load_session(tmp_path / "s.toml")
    assert session.simulator.faults == Faults(**CHOSEN)

    # the launcher's command line, parsed by sim serve's own parser, gives the same faults back
    started = []

    class Process:
        def __init__(self, cmd, quiet, where):
            started.append(cmd)
            self.endpoint, self.stop = "/dev/null", lambda: None

    monkeypatch.setattr(sim_serve, "SimulatorProcess", Process)   # the command line, not the process
    sim_serve.launch(session.simulator, session, True)
    argv = started[0][started[0].index("sim"):]
    args = build_parser().parse_args(argv)
    assert Faults(**{f.name: getattr(args, f.name) for f in fields(Faults)}) == Faults(**CHOSEN)
    assert all(fault_flag(f.name) in argv for f in fields(Faults))
