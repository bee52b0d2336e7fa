"""Acquisition session config (TOML, docs/acquisition.md) -> validated frozen dataclasses.

Every mistake is reported up front as one DaqError line naming the file and the item (a channel of
unknown kind, a sensitivity without its unit, a channel mapped to no device, a port that does not exist,
...), before any device is opened.

Conversion to physical units (stored values): a device delivers each *source* (a frame column, a DBC
signal, a register) in device units; the channel then applies
``value = (raw * scale + offset) / sensitivity * k`` where ``sensitivity`` is given in
``sensitivity_unit = "<electrical>/<physical>"`` (e.g. ``mV/g``), ``scale``/``offset`` bring the device
value to the electrical unit (e.g. mV per ADC count) and ``k`` converts the sensitivity's physical unit
to the channel's ``unit`` (e.g. g -> m/s^2 = 9.80665, rev -> deg = 360).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from flexmodal.checked_io.text import read_toml, regular_file
from flexmodal.checked_io.toml_fields import Fields, range_rule
from flexmodal.daq.devices import SIMULATOR_PORT, Device
from flexmodal.daq.errors import DaqError
from flexmodal.daq.faults import Faults
from flexmodal.daq.protocols import PROTOCOLS, registered_protocols
from flexmodal.daq.run_schema import (
    CHANNEL_KINDS,
    EXCITATIONS,
    MAX_SENSITIVITY,
    MIN_SENSITIVITY,
    check_run_id,
    kind_unit_fault,
)
from flexmodal.daq.store import Channel

# Whole-number fields whose range every protocol shares (a TCP port given as a number, the Modbus unit id).
INT_RANGES = {"baud": (1, 100_000_000), "bitrate": (1, 100_000_000), "device_id": (0, 247),
              "port": (1, 65535)}
MIN_HIT_SAMPLES = 16  # samples of an impact window after its pretrigger samples (an FFT needs a few)
G_M_PER_S2 = 9.80665
NUMBER = r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
EFFECT_PATTERN = rf"\w+@[\w.@-]+:\w+={NUMBER}(,\w+={NUMBER})*"
MIN_GAIN, MAX_GAIN = 1e-15, 1e15  # physical units per device unit (an ADC count, a mV, ...)
# factor converting one unit of the first name to the second (sensitivity denominator -> channel unit)
UNIT_FACTORS = {
    ("g", "m/s^2"): G_M_PER_S2, ("m/s^2", "g"): 1 / G_M_PER_S2, ("mm/s^2", "m/s^2"): 1e-3,
    ("m/s^2", "mm/s^2"): 1e3, ("kN", "N"): 1e3, ("N", "kN"): 1e-3,
    ("lbf", "N"): 4.4482216152605, ("rev", "deg"): 360.0, ("rev", "rad"): 2 * math.pi,
    ("deg", "rad"): math.pi / 180, ("rad", "deg"): 180 / math.pi, ("ε", "µε"): 1e6, ("µε", "ε"): 1e-6,
    ("ue", "µε"): 1.0, ("με", "µε"): 1.0, ("microstrain", "µε"): 1.0, ("mN", "N"): 1e-3,
    ("mm/s", "m/s"): 1e-3, ("m/s", "mm/s"): 1e3,
}


@dataclass(frozen=True)
class ChannelMap:
    """A stored channel and where its values come from."""

    channel: Channel
    device: str
    source: str
    scale: float = 1.0
    offset: float = 0.0
    factor: float = 1.0  # sensitivity denominator unit -> channel unit
    full_scale: float = math.inf  # |value| >= full_scale is an overload (channel units)

    def gain(self) -> float:
        """Physical value per raw device unit: (raw * scale + offset) / sensitivity * factor."""
        return self.scale / self.channel.sensitivity * self.factor


@dataclass(frozen=True)
class Trigger:
    channel: str
    level: float
    slope: str = "rising"  # rising | falling
    pretrigger_samples: int = 0
    holdoff_s: float = 0.5
    start: bool = False  # the run starts pretrigger_samples before the first trigger
    response: str = ""  # impact sessions: the channel of the live H1 (default: first acceleration)
    window_s: float = 1.0  # impact sessions: record length of one hit (from pretrigger_samples before)
    min_peak: float | None = None  # impact sessions: weaker hits are rejected (default 2 x level)


@dataclass(frozen=True)
class Simulator:
    """The simulator a session starts itself (docs/acquisition.md): only these validated options.

    ``fault_log`` is a file name inside the run file's folder (never elsewhere).
    """

    protocol: str
    rig: str = ""
    test: str = "impact"
    seed: int = 0
    pose: dict = field(default_factory=dict)
    faults: Faults = Faults()
    scans_per_frame: int = 32
    format: str = "int16"
    fault_log: str = ""
    effects: tuple[str, ...] = ()  # hidden effects "EFFECT@LOCATION:PARAM=VALUE,..." (SI units)


@dataclass(frozen=True)
class Session:
    source: Path
    sample_rate_hz: float
    devices: tuple[Device, ...]
    channels: tuple[ChannelMap, ...]
    excitation: str = "operational"
    duration_s: float | None = None
    run_id: str = ""
    notes: str = ""
    pose: dict = field(default_factory=dict)
    pose_from: dict = field(default_factory=dict)  # pose variable -> encoder channel name (degrees)
    trigger: Trigger | None = None
    simulator: Simulator | None = None
    reconnect_timeout_s: float = 10.0  # a device silent this long is lost
    continue_on_device_loss: bool = False  # False: a lost device ends the session (exit 2)


def unit_factor(from_unit: str, to_unit: str) -> float | None:
    """Factor converting ``from_unit`` to ``to_unit`` (None when unknown)."""
    norm = lambda u: u.replace("m/s2", "m/s^2").replace("m/s²", "m/s^2").replace("μ", "µ").strip()
    a, b = norm(from_unit), norm(to_unit)
    return 1.0 if a == b else UNIT_FACTORS.get((a, b))


SI_PREFIXES = {"": 1.0, "k": 1e3, "m": 1e-3, "µ": 1e-6, "μ": 1e-6, "u": 1e-6}


def source_unit_fault(cm: ChannelMap, source_unit: str) -> str | None:
    """Why the value a device labels ``source_unit`` (a DBC signal's unit) cannot feed channel map
    ``cm`` as it stands, else None: it is the unit ``scale`` must bring to (the sensitivity's electrical
    unit, else the channel's unit) up to an SI prefix (V against mV: 1000x), and no ``scale`` converts
    it.  Units of other names ('counts', 'LSB') are not judged: scale and sensitivity may well apply.

    Examples
    --------
    >>> from flexmodal.daq.store import Channel
    >>> a1 = ChannelMap(Channel("a1", "acceleration", "m/s^2", 100.0, "mV/g"), "can", "a1")
    >>> print(source_unit_fault(a1, "V"))
    source 'a1' is in V (its DBC unit) but the sensitivity expects mV (100 mV/g): give scale = 1000 (V to mV)
    >>> source_unit_fault(a1, "mV") is None, source_unit_fault(a1, "counts") is None
    (True, True)
    """
    want = cm.channel.sensitivity_unit.split("/")[0].strip() if cm.channel.sensitivity_unit else \
        cm.channel.unit
    if cm.scale != 1.0 or source_unit == want:
        return None
    for p, f in SI_PREFIXES.items():
        base = source_unit[len(p):] if source_unit.startswith(p) else ""
        for q, g in SI_PREFIXES.items():
            if p != q and base[:1].isalpha() and want == q + base:
                into = ("the sensitivity expects " + want + f" ({cm.channel.sensitivity:g} "
                        f"{cm.channel.sensitivity_unit})") if cm.channel.sensitivity_unit else \
                    f"the channel's unit is {want}"
                return (f"source {cm.source!r} is in {source_unit} (its DBC unit) but {into}: give scale = "
                        f"{f / g:g} ({source_unit} to {want})")
    return None


class Table(Fields):
    """Typed access to one table of a session config (:class:`flexmodal.checked_io.toml_fields.Fields` with
    ``DaqError``, ``key = value`` wording and the shared whole-number ranges); ``base``: the folder
    relative paths are taken from (the session file's)."""

    def __init__(self, doc: Any, where: str, base: Path = Path()) -> None:
        super().__init__(doc, where, DaqError, ranges=INT_RANGES)
        self.base = base

    def port(self, key: str) -> str:
        """A port path that must exist (or a URL such as loop://, or the simulator placeholder)."""
        port = self.get(key, str)
        if not port.strip():   # pyserial's "could not open port : ... ''" named neither the file nor the key
            raise DaqError(f"{self.where}: {key} is empty ({port!r}): name a device path such as "
                           f"/dev/ttyUSB0, a URL such as loop://, or {SIMULATOR_PORT!r}")
        scheme, url, _ = port.partition("://")
        if url and not _serial_url_scheme(scheme):
            raise DaqError(f"{self.where}: {key} {port!r}: pyserial knows no {scheme!r}:// URL (loop://, "
                           "socket://, rfc2217://, spy://, ... or a device path such as /dev/ttyUSB0)")
        if not (url or port == SIMULATOR_PORT or self._exists(port, key)):
            raise DaqError(f"{self.where}: {key} {port!r} does not exist")
        return port

    def _exists(self, path: str, what: str) -> bool:
        """Whether ``path`` exists; DaqError naming ``what`` when the system cannot even look (a name
        too long for the file system: pathlib raises OSError there, not False)."""
        try:
            return Path(path).exists()
        except OSError as exc:
            raise DaqError(f"{self.where}: {what} {path[:60]!r}... cannot be looked up ({exc.strerror}, "
                           f"{len(path)} characters)") from None

    def file(self, key: str, what: str) -> str:
        """A file path relative to ``base`` that must exist (absolute after this)."""
        path = _resolve(self.base, self.get(key, str))
        if not self._exists(path, what):
            raise DaqError(f"{self.where}: {what} {path!r} does not exist")
        regular_file(path, lambda text: DaqError(f"{self.where}: {text}"), what)  # a FIFO would block
        return path


def _serial_url_scheme(scheme: str) -> bool:
    """Whether pyserial's ``serial_for_url`` has a handler for ``scheme://`` (its
    ``serial.urlhandler.protocol_<scheme>`` module)."""
    import importlib.util

    if not scheme.isidentifier():
        return False
    try:
        return importlib.util.find_spec(f"serial.urlhandler.protocol_{scheme.lower()}") is not None
    except (ImportError, ValueError):
        return False


class DeviceTable(Table):
    """A ``[[device]]`` table: ``name`` and ``protocol`` are known fields of every protocol."""

    def reject_unknown(self, known: set[str]) -> None:
        super().reject_unknown(known | {"name", "protocol"})


def _resolve(base: Path, value: str) -> str:
    return str((base / value).resolve()) if value and not Path(value).is_absolute() else value


def _device(doc: dict, where: str, base: Path) -> Device:
    t = Table(doc, where, base)
    name = t.name("name")
    t = DeviceTable(doc, f"{where.split(':')[0]}: device {name!r}", base)
    protocol = t.choice("protocol", registered_protocols())
    device = PROTOCOLS.entry(protocol).parse_device(t, name)
    sources = PROTOCOLS.entry(protocol).known_sources(device) or ()
    twice = [s for i, s in enumerate(sources) if s in sources[:i]]
    if twice:   # a channel naming it would read one of the two values, which one unsaid
        raise DaqError(f"{t.where}: source {twice[0]!r} is named twice among its sources "
                       f"({', '.join(sources)})")
    return device


def _channel(doc: dict, where: str, devices: dict[str, Device]) -> ChannelMap:
    t = Table(doc, where)
    name = t.name("name")
    where = f"{where.split(':')[0]}: channel {name!r}"
    t = Table(doc, where)
    t.reject_unknown({"name", "kind", "unit", "sensitivity", "sensitivity_unit", "scale", "offset",
                      "location", "direction", "device", "source", "full_scale", "counts_per_rev"})
    kind = t.choice("kind", CHANNEL_KINDS)
    unit = t.get("unit", str)
    if kind_unit_fault(kind, unit):
        raise DaqError(f"{where}: {kind_unit_fault(kind, unit)}")
    sensitivity = t.number("sensitivity", 1.0, lo=MIN_SENSITIVITY, hi=MAX_SENSITIVITY,
                           why=f"{range_rule(MIN_SENSITIVITY, MAX_SENSITIVITY)} (a calibration value > 0; "
                               "the sign of an axis is its direction)")
    sens_unit = t.get("sensitivity_unit", str, "")
    if "counts_per_rev" in t.doc:  # an encoder's resolution: counts -> angle in `unit` (deg or rad)
        if kind != "encoder" or "sensitivity" in t.doc or unit not in ("deg", "rad"):
            raise DaqError(f"{where}: counts_per_rev is for kind = \"encoder\" with unit deg or rad and no "
                           "sensitivity")
        sensitivity = t.number("counts_per_rev", lo=MIN_SENSITIVITY, hi=MAX_SENSITIVITY)
        sens_unit = "counts/rev"
    elif "sensitivity" in t.doc and not sens_unit:
        raise DaqError(f"{where}: sensitivity {sensitivity} has no sensitivity_unit (e.g. \"mV/g\")")
    factor = 1.0
    if sens_unit:
        m = re.fullmatch(r"\s*([^/]+?)\s*/\s*(.+?)\s*", sens_unit)
        if not m:
            raise DaqError(f"{where}: sensitivity_unit {sens_unit!r} is not '<electrical>/<physical>'")
        found = unit_factor(m.group(2).strip("()"), unit)
        if found is None:
            raise DaqError(f"{where}: cannot convert {m.group(2)!r} (from sensitivity_unit) to unit {unit!r}")
        factor = found
    device = t.get("device", str)
    if device not in devices:
        raise DaqError(f"{where}: device {device!r} is not a device of this session "
                       f"({', '.join(devices) or 'none defined'})")
    dev = devices[device]
    source = t.get("source", str, name)
    known = PROTOCOLS.entry(dev.protocol).known_sources(dev)
    if known is not None and source not in known:
        raise DaqError(f"{where}: source {source!r} is not one of device {device!r}'s {', '.join(known)}")
    scale = t.get("scale", float, 1.0, check=bool, why="must be finite and non-zero (0 records zeros)")
    offset = t.get("offset", float, 0.0)
    gain = scale / sensitivity * factor
    if not MIN_GAIN <= abs(gain) <= MAX_GAIN or abs(offset / sensitivity * factor) > MAX_GAIN:
        raise DaqError(f"{where}: scale = {scale:g}, offset = {offset:g} and sensitivity = {sensitivity:g} "
                       "give "
                       f"{gain:g} {unit} per device unit (offset {offset / sensitivity * factor:g}): out of "
                       f"range ({MIN_GAIN:g} to {MAX_GAIN:g} in magnitude; the values would underflow or "
                       "overflow)")
    return ChannelMap(
        Channel(name, kind, unit, sensitivity, sens_unit, t.get("location", str, ""),
                t.get("direction", str, "")),
        device, source, scale=scale, offset=offset, factor=factor,
        full_scale=t.number("full_scale", math.inf, lo=0, lo_open=True))


def _simulator(doc: dict, where: str, base: Path) -> Simulator:
    """The ``[simulator]`` block: known options only, each value checked (no free-form arguments)."""
    s = Table(doc, where, base)
    faults = fields(Faults)
    s.reject_unknown({"protocol", "rig", "test", "seed", "pose", "scans_per_frame", "format", "fault_log",
                      "effects"} | {f.name for f in faults})
    log = s.get("fault_log", str, "", check=lambda v: v == Path(v).name and v not in (".", ".."),
                why="must be a plain file name (it is written in the run file's folder)")
    return Simulator(
        protocol=s.choice("protocol", registered_protocols()),
        rig=s.file("rig", "rig file") if "rig" in doc else "",
        test=s.choice("test", ("impact", "random", "sweep", "operational", "moving"), "impact"),
        seed=s.get("seed", int, 0, check=lambda v: 0 <= v < 2**32, why="must be in [0, 2**32)"),
        pose=s.numbers("pose"),
        faults=Faults(**{f.name: s.number(f.name, f.default, unit="s" if f.name.endswith("_s") else "",
                                          **f.metadata["range"]) for f in faults}),
        scans_per_frame=s.get("scans_per_frame", int, 32, check=lambda v: 1 <= v <= 4096,
                              why="must be in 1..4096"),
        format=s.choice("format", ("int16", "int32", "float32"), "int16"), fault_log=log,
        effects=tuple(s.get("effects", list, [], check=lambda v: all(
            isinstance(e, str) and re.fullmatch(EFFECT_PATTERN, e) for e in v),
            why="must be a list of \"EFFECT@LOCATION:PARAM=NUMBER,...\"")))


def parse_session(doc: dict, source: Path) -> Session:
    """Validate a parsed session TOML document (paths relative to the file's folder)."""
    where = str(source)
    t = Table(doc, where)
    t.reject_unknown({"sample_rate_hz", "duration_s", "excitation", "run_id", "notes", "pose", "pose_from",
                      "trigger", "simulator", "device", "channel", "reconnect_timeout_s",
                      "continue_on_device_loss"})
    rate = t.number("sample_rate_hz", lo=0, hi=1e7, lo_open=True, hi_open=True, unit="Hz")
    base = source.resolve().parent
    sim = _simulator(doc["simulator"], f"{where}: simulator", base) if "simulator" in doc else None
    dev_docs = t.get("device", list, check=bool, why="must list at least one [[device]]")
    devices: dict[str, Device] = {}
    for i, d in enumerate(dev_docs):
        dev = _device(d, f"{where}: device {i + 1}", base)
        if dev.name in devices:
            raise DaqError(f"{where}: device {dev.name!r} is defined twice")
        devices[dev.name] = dev
    uses_sim = any(SIMULATOR_PORT in vars(d.config).values() for d in devices.values())
    if uses_sim and sim is None:
        raise DaqError(f"{where}: a device uses port {SIMULATOR_PORT!r} but there is no [simulator]")
    if sim is not None and not any(d.protocol == sim.protocol for d in devices.values()):
        have = ", ".join(f"{d.name} ({d.protocol})" for d in devices.values())
        raise DaqError(f"{where}: simulator: protocol = {sim.protocol!r} but no [[device]] speaks it "
                       f"(devices: {have})")
    ch_docs = t.get("channel", list, check=bool, why="must list at least one [[channel]]")
    channels = tuple(_channel(c, f"{where}: channel {i + 1}", devices) for i, c in enumerate(ch_docs))
    names = [c.channel.name for c in channels]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise DaqError(f"{where}: channel {dup[0]!r} is defined twice")
    for dev in devices.values():
        if not any(c.device == dev.name for c in channels):
            raise DaqError(f"{where}: device {dev.name!r} has no channel mapped to it")
    trigger = None
    if "trigger" in doc:
        g = Table(doc["trigger"], f"{where}: trigger")
        g.reject_unknown({"channel", "level", "slope", "pretrigger_samples", "holdoff_s", "start", "response",
                          "window_s", "min_peak"})
        trigger = Trigger(g.get("channel", str, check=lambda v: v in names, why="is not a channel"),
                          g.get("level", float), g.choice("slope", ("rising", "falling"), "rising"),
                          g.get("pretrigger_samples", int, 0, check=lambda v: v >= 0, why="must be >= 0"),
                          g.number("holdoff_s", 0.5, lo=0, hi=1e9, unit="s"),   # as --duration: 31.7 years
                          g.get("start", bool, False),
                          g.get("response", str, "", check=lambda v: v in names, why="is not a channel"),
                          g.number("window_s", 1.0, lo=0, hi=60, lo_open=True, unit="s"),
                          g.number("min_peak", None, lo=0))
        window = int(trigger.window_s * rate)
        if window < trigger.pretrigger_samples + MIN_HIT_SAMPLES:
            raise DaqError(f"{where}: trigger: window_s = {trigger.window_s:g} s holds {window} samples at "
                           f"{rate:g} Hz; a hit needs at least pretrigger_samples + {MIN_HIT_SAMPLES} = "
                           f"{trigger.pretrigger_samples + MIN_HIT_SAMPLES}")
    pose = t.numbers("pose")
    pose_from = t.get("pose_from", dict, {})
    kinds = {c.channel.name: c.channel.kind for c in channels}
    for k, v in pose_from.items():
        if v not in names:
            raise DaqError(f"{where}: pose_from.{k} = {v!r} is not a channel")
        if kinds[v] != "encoder":   # its mean (say m/s^2) would be stored as the pose in degrees
            raise DaqError(f"{where}: pose_from.{k} = {v!r} is a channel of kind {kinds[v]!r}; a pose is "
                           "taken from an encoder channel (kind = \"encoder\", degrees)")
        if k in pose:
            raise DaqError(f"{where}: pose variable {k!r} is given in pose and in pose_from (one of them)")
    variables = [*pose, *pose_from]
    twice = [v for v in variables if [w.casefold() for w in variables].count(v.casefold()) > 1]
    if twice:   # theta_deg and Theta_deg: two pose columns of one variable in every table made from the run
        raise DaqError(f"{where}: pose variables {twice[0]!r} and {twice[1]!r} differ only by case (one "
                       "variable given twice, or two no reader tells apart: rename one)")
    if trigger is not None and trigger.response and kinds[trigger.response] == "force":
        raise DaqError(f"{where}: trigger: response = {trigger.response!r} is a force channel; the live "
                       "H1 of a hit is response / force (name an acceleration or strain channel)")
    return Session(
        source=source, sample_rate_hz=rate, devices=tuple(devices.values()), channels=channels,
        excitation=t.choice("excitation", EXCITATIONS, "operational"),
        duration_s=t.number("duration_s", None, lo=0, lo_open=True),
        run_id=t.name("run_id", "") and check_run_id(t.doc["run_id"], f"{where}: run_id"),
        notes=t.get("notes", str, ""), pose=pose, pose_from=dict(pose_from), trigger=trigger,
        simulator=sim,
        reconnect_timeout_s=t.number("reconnect_timeout_s", 10.0, lo=0, hi=3600, lo_open=True, unit="s"),
        continue_on_device_loss=t.get("continue_on_device_loss", bool, False))


def load_session(path: str | Path) -> Session:
    """Read and validate a session TOML file."""
    return parse_session(read_toml(path, DaqError, "session config"), Path(path))
