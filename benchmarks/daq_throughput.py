"""Acquisition throughput against each protocol's simulator and against the library's own limits.

    python benchmarks/daq_throughput.py [--seconds S] [--out-dir DIR]

1. Serial, binary frames over a pty into HDF5 (the full `flexmodal acquire` path: reader thread, queue,
   timeline, SWMR writer): 32 channels at 64 kHz (2.048 MS/s) and 256 kHz (8.19 MS/s) paced in real
   time, checked for zero loss
   (no gap/corrupt event, every value equal to what the simulator sent); then the simulator unpaced to
   find the highest sustained rate.
2. The HDF5 writer alone (RunWriter.append in 0.1 s blocks, float32) against a raw numpy write of the same
   bytes to the same disk: the ratio of the two rates.
3. CAN over slcan on a pty: frames/s decoded by the CAN driver against python-can's own receive loop
   (Bus.recv) over the same byte stream.
4. Modbus TCP on 127.0.0.1: polls/s of the Modbus driver against pymodbus's own request/response loop.
5. Overrun: each protocol's example session (its simulator started by the session) run below and above
   the rate its stack sustains; above it the writer falls behind real time and `acquire` records an
   `overrun` event (and warns in the live view) once it lags by more than 1 s.
Prints one line per measurement and the ratios; results go to stdout.
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing as mp
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from flexmodal.daq.acquire import acquire  # noqa: E402
from flexmodal.daq.can_driver import CanConfig  # noqa: E402
from flexmodal.daq.modbus_driver import ModbusConfig, Register  # noqa: E402
from flexmodal.daq.serial_driver import SerialConfig  # noqa: E402
from flexmodal.daq.session import ChannelMap, Device, Session  # noqa: E402
from flexmodal.daq.store import Channel, RunWriter, list_runs, read_run  # noqa: E402
from flexmodal.fixtures.sim_common import PtyLink  # noqa: E402
from flexmodal.fixtures.sim_source import LSB_MV, SimChannel, SimSource  # noqa: E402

N_CH, RATE_HZ = 32, 64_000.0


def synthetic_source(n_ch: int, rate_hz: float, n: int = 1 << 15) -> SimSource:
    counts = np.random.default_rng(0).integers(-32768, 32768, (n, n_ch)).astype(np.int32)
    chans = tuple(SimChannel(f"c{i}", "voltage", "mV", 1.0, "", LSB_MV, 1.0, "", "") for i in range(n_ch))
    return SimSource(chans, rate_hz, counts)


def serial_session(port: str, n_ch: int, rate_hz: float) -> Session:
    names = tuple(f"c{i}" for i in range(n_ch))
    dev = Device("adc", "serial", SerialConfig(port, tuple(names), baud=12_000_000))
    maps = tuple(ChannelMap(Channel(n, "other", "mV"), "adc", n, scale=LSB_MV) for n in names)
    return Session(Path("benchmark.toml"), rate_hz, (dev,), maps, run_id="bench")


def _serve_serial(link: PtyLink, source: SimSource, seconds: float, speed: float) -> None:
    from flexmodal.fixtures.sim_serial import serve

    serve(link, source, scans_per_frame=256, duration_s=seconds, speed=speed)


def bench_serial(out_dir: Path, seconds: float, speed: float, rate_hz: float = RATE_HZ) -> tuple[float, bool]:
    """Samples/s stored (all channels) and whether everything the simulator sent arrived intact."""
    source = synthetic_source(N_CH, rate_hz)
    link = PtyLink()
    sim = mp.get_context("fork").Process(target=_serve_serial, args=(link, source, seconds + 2, speed))
    out = out_dir / f"serial-{speed:g}.h5"
    out.unlink(missing_ok=True)
    sim.start()
    t0 = time.perf_counter()
    summary = acquire(serial_session(str(link.path), N_CH, rate_hz), out, duration_s=seconds, quiet=True)
    elapsed = time.perf_counter() - t0
    sim.terminate()
    sim.join()
    link.remove()
    run = read_run(out, list_runs(out)[0])
    first = int(next(iter(json.loads(run.attrs["first_index"]).values())))
    exact = np.array_equal(run.samples, source.physical(first, run.samples.shape[0]).astype(np.float32))
    faults = any(e.kind in ("gap", "corrupt") for e in run.events) or summary.dropped_blocks > 0
    intact = exact and not faults
    return summary.n_samples * N_CH / elapsed, intact


def bench_writer(out_dir: Path, total_mb: float = 256.0) -> tuple[float, float]:
    """MB/s of RunWriter.append and of a raw numpy write of the same blocks to the same directory."""
    block = np.random.default_rng(1).standard_normal((int(RATE_HZ / 10), N_CH)).astype(np.float32)
    n_blocks = int(total_mb * 1e6 / block.nbytes)
    chans = tuple(Channel(f"c{i}", "voltage", "V") for i in range(N_CH))
    h5, raw = out_dir / "writer.h5", out_dir / "raw.bin"
    h5.unlink(missing_ok=True)
    t0 = time.perf_counter()
    with RunWriter(h5, "w", sample_rate_hz=RATE_HZ, channels=chans, excitation="random", pose={}) as w:
        for _ in range(n_blocks):
            w.append(block)
    os.sync()
    t_h5 = time.perf_counter() - t0
    t0 = time.perf_counter()
    with open(raw, "wb") as f:
        for _ in range(n_blocks):
            block.tofile(f)
    os.sync()
    t_raw = time.perf_counter() - t0
    mb = n_blocks * block.nbytes / 1e6
    h5.unlink()
    raw.unlink()
    return mb / t_h5, mb / t_raw


def _slcan_stream(n_frames: int) -> bytes:
    from flexmodal.fixtures.sim_can import FRAME_ID, encode

    frames = encode(synthetic_source(7, 1000.0), 0, -(-n_frames // 3))[:n_frames]
    return b"".join(f"t{FRAME_ID:03X}8{f.tobytes().hex().upper()}\r".encode() for f in frames)


def _feed(link: PtyLink, data: bytes, delay_s: float = 0.3) -> None:
    time.sleep(delay_s)
    link.write(data, timeout_s=10)


def bench_can(n_frames: int = 30000) -> tuple[float, float]:
    """Frames/s through python-can's own slcan Bus.recv loop and through the CAN driver (recv + decode)."""
    import can

    from flexmodal.daq.can_driver import CanDriver
    from flexmodal.fixtures.sim_can import DEMO_DBC

    data = _slcan_stream(n_frames)
    rates = []
    for use_driver in (False, True):
        link = PtyLink()
        feeder = threading.Thread(target=_feed, args=(link, data))
        if use_driver:
            dev = Device("can0", "can", CanConfig("slcan", str(link.path), str(DEMO_DBC)))
            drv = CanDriver(dev, 1000.0)
            drv.open()
            feeder.start()
            seen, got, t0 = 0, 0, None
            while seen < n_frames - 3 * 2:  # the newest scan is held back until the next one starts
                n = 3 * sum(b.values.shape[0] for b in drv.read())  # three frames a scan
                seen += n
                if t0 is not None:
                    got += n
                elif n:
                    t0 = time.perf_counter()  # count from the end of the first read
            drv.close()
        else:
            bus = can.Bus(interface="slcan", channel=str(link.path), sleep_after_open=0)
            feeder.start()
            seen, got, t0 = 0, 0, None
            while seen < n_frames:
                if bus.recv(timeout=1.0) is not None:
                    seen += 1
                    got += t0 is not None
                    t0 = t0 or time.perf_counter()  # count from the first frame
            bus.shutdown()
        rates.append(got / (time.perf_counter() - t0))
        feeder.join()
        link.remove()
    return rates[0], rates[1]


def bench_modbus(seconds: float = 3.0) -> tuple[float, float]:
    """Polls/s: pymodbus's own read loop, and the Modbus driver polling as fast as it can."""
    from pymodbus.client import ModbusTcpClient

    from flexmodal.daq.modbus_driver import ModbusDriver
    from flexmodal.fixtures.sim_modbus import free_port, serve

    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    port = free_port()
    stop = threading.Event()
    ready = threading.Event()
    kwargs = {"port": port, "stop": stop, "announce": lambda _: ready.set()}
    server = threading.Thread(target=serve, args=(synthetic_source(7, 1000.0),), kwargs=kwargs,
                              daemon=True)
    server.start()
    ready.wait(10)
    client = ModbusTcpClient("127.0.0.1", port=port)
    client.connect()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        client.read_holding_registers(0, count=9, device_id=1)
        n += 1
    raw_rate = n / (time.perf_counter() - t0)
    client.close()
    regs = tuple(Register(f"r{i}", i) for i in range(9))
    drv = ModbusDriver(Device("plc", "modbus", ModbusConfig("tcp", regs, tcp_port=port)), 1e6)
    drv.open()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        n += sum(b.values.shape[0] for b in drv.read())
    ours = n / (time.perf_counter() - t0)
    drv.close()
    stop.set()
    server.join(5)
    return raw_rate, ours


def bench_overrun(protocol: str, rate_hz: float, seconds: float, out_dir: Path) -> tuple[int, float]:
    """Run ``protocol``'s example session at ``rate_hz`` for ``seconds`` of samples; returns the number
    of overrun events and the lag (s) the first one reported (nan without one)."""
    import tomllib

    from flexmodal.daq.session import parse_session

    path = Path(__file__).resolve().parents[1] / "examples" / "sessions" / f"{protocol}-sim.toml"
    doc = tomllib.loads(path.read_text())
    doc["sample_rate_hz"] = rate_hz
    doc.pop("trigger")  # record from the start
    if protocol == "modbus":  # a logger whose 2 s FIFO lets a poller slower than its counter fall behind
        doc["simulator"]["modbus_fifo_s"] = 2.0  # (more than the 1 s that makes an overrun)
    out = out_dir / f"overrun-{protocol}-{rate_hz:g}.h5"
    out.unlink(missing_ok=True)
    summary = acquire(parse_session(doc, path), out, duration_s=seconds, quiet=True)
    events = [e for e in read_run(out, summary.run_id).events if e.kind == "overrun"]
    return len(events), events[0].count / rate_hz if events else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=5.0, help="length of the serial runs, s")
    parser.add_argument("--out-dir", type=Path, help="where to write the test files (default: a temp dir)")
    parser.add_argument("--serial-rates", type=float, nargs="+", default=[RATE_HZ, 4 * RATE_HZ], metavar="HZ",
                        help="per-channel rates of the paced serial runs (default 64 kHz and 256 kHz)")
    args = parser.parse_args()
    out_dir = args.out_dir or Path(tempfile.mkdtemp(prefix="flexmodal-bench-"))
    for serial_rate in args.serial_rates:
        rate, intact = bench_serial(out_dir, args.seconds, 1.0, serial_rate)
        print(f"serial binary over pty, paced {N_CH} ch x {serial_rate:g} Hz: {rate / 1e6:.3f} MS/s stored, "
              f"zero loss: {intact}")
    rate, intact = bench_serial(out_dir, args.seconds, 50.0)
    print(f"serial binary over pty, unpaced: {rate / 1e6:.3f} MS/s stored, zero loss: {intact}")
    h5, raw = bench_writer(out_dir)
    print(f"HDF5 writer alone {h5:.0f} MB/s vs raw numpy write {raw:.0f} MB/s: ratio {h5 / raw:.2f}")
    lib, ours = bench_can()
    print(f"CAN slcan: python-can Bus.recv {lib:.0f} frames/s, CAN driver (recv + DBC decode) {ours:.0f} "
          f"frames/s: ratio {ours / lib:.2f}")
    lib, ours = bench_modbus()
    print(f"Modbus TCP: pymodbus read loop {lib:.0f} polls/s, Modbus driver {ours:.0f} polls/s: "
          f"ratio {ours / lib:.2f}")
    for protocol, rates in (("can", (512.0, 4096.0)), ("modbus", (200.0, 8000.0))):
        for rate in rates:
            n, lag = bench_overrun(protocol, rate, args.seconds, out_dir)
            print(f"{protocol} session at {rate:g} Hz for {args.seconds:g} s: {n} overrun event(s)"
                  + (f", first at {lag:.2f} s behind real time" if n else ""))


if __name__ == "__main__":
    main()
