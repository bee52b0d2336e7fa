"""Universal File Format interchange through pyuff (dataset 58: functions at nodes; dataset 55: mode
shapes), so FRFs and modes open in ME'scope, Simcenter Testlab and similar tools.

Read: dataset 58 of function type 4 (FRF, with the exponential-window decay flexmodal notes in an id
line; other function types in the same file are left aside) or 1
(time response; the force channels are those whose ordinate is a force, data type 13).  Time
responses with several records per channel (an impact test exported hit by hit, the hits told apart
by load case id, record number or order) are assembled into hits of equal length.  Channels are
named ``<node><sign><axis>`` (e.g. ``3+z``) from
the node and direction codes; sensors sharing a node and direction (direction code 0: skewed or
tri-axial sensors) are told apart by their ID line, else by their order within a load case
(``5:0#1``, ``5:0#2``).  Records of one quantity whose unit labels differ (g beside m/s^2, kN
beside N) are brought to the SI unit of that quantity, as a run's channels are (docs/formats.md).  Write: FRFs
as dataset 58 type 4, modes as dataset 55 (real, three components per node, the shape value in the
channel's direction)."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexmodal.checked_io.output import atomic_path
from flexmodal.checked_io.text import fits_in_memory
from flexmodal.checked_io.uff_blocks import check_blocks
from flexmodal.daq.run_schema import MAX_SAMPLE_RATE_HZ
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.valid_uff import check_functions, drop_line_padding

_AXES = "xyz"
_SPEC = {"accelerance": 12, "mobility": 11, "receptance": 8}
_QUANTITY = {v: k for k, v in _SPEC.items()}
_DECAY = re.compile(r"exponential window decay ([0-9.eE+-]+) 1/s")   # flexmodal's note in an id line


def channel_name(node: int, direction: int) -> str:
    d = int(direction)
    if 1 <= abs(d) <= 3:
        return f"{int(node)}{'+' if d > 0 else '-'}{_AXES[abs(d) - 1]}"
    return f"{int(node)}:{d}"


def _node_dir(name: str, default_node: int) -> tuple[int, int]:
    """(node, direction) of a channel named ``<node><+|-><x|y|z>`` whose node fits a UFF node field
    (ASCII digits below 2^31: a superscript or 5000 digits name no node); else ``default_node``, +z."""
    node = name[:-2].lstrip("0") or "0"
    if len(name) >= 3 and name[-2] in "+-" and name[-1] in _AXES and node.isascii() and node.isdigit() \
            and len(node) <= 10 and int(node) < 2**31:
        return int(node), (1 if name[-2] == "+" else -1) * (_AXES.index(name[-1]) + 1)
    return default_node, 3


@dataclass(frozen=True)
class UffFrfs:
    freq_hz: np.ndarray
    H: np.ndarray
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    quantity: str
    decay_rate_per_s: float = 0.0


@dataclass(frozen=True)
class UffRecord:
    """Time histories [n_samples, n_channels].  When each channel holds several records (hits stored
    as load cases or record numbers), the hits are laid end to end: ``hit_len`` samples each, hit k
    starting at sample k * hit_len, with ``triggers`` the sample of each hit's impact (None: one
    continuous record)."""

    samples: np.ndarray
    sample_rate_hz: float
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    hit_len: int | None = None
    triggers: tuple[int, ...] | None = None


def read_uff(path: str | Path) -> UffFrfs | UffRecord:
    """FRFs (type 4) or a time record (type 1) from the dataset-58 sets of a UFF file."""
    import pyuff

    p = fits_in_memory(path, ModalError, "UFF file")   # pyuff holds the text and its arrays at once
    try:
        numbers = check_blocks(p, p.read_bytes(), ModalError)
        sets = pyuff.UFF(str(p)).read_sets()
    except ModalError:
        raise
    except Exception as exc:  # pyuff raises bare Exceptions on malformed files
        raise ModalError(f"{p}: not a readable UFF file ({exc})") from None
    sets = [sets] if isinstance(sets, dict) else list(sets)
    read = sum(s.get("type") == 58 for s in sets)
    if read != numbers.count(58):
        raise ModalError(f"{p}: {numbers.count(58) - read} of its {numbers.count(58)} dataset-58 records "
                         "could not be read (a damaged header line?)")
    if not sets:
        raise ModalError(f"{p}: no dataset found (not a UFF file, or one pyuff cannot read)")
    types = sorted({int(s.get("type", -1)) for s in sets})
    _check_units(p, [s for s in sets if s.get("type") == 164])
    funcs = drop_line_padding([s for s in sets if s.get("type") == 58])
    if not funcs:
        raise ModalError(f"{p}: no dataset 58 (found dataset types {types}; only 58 is read)")
    check_functions(p, funcs)
    kinds = sorted({int(s.get("func_type", 0)) for s in funcs})
    try:
        if 4 in kinds:   # FRFs, whatever else (coherence, spectra) the file holds besides
            return _frfs(p, [s for s in funcs if int(s.get("func_type", 0)) == 4])
        if 1 in kinds:
            return _record(p, [s for s in funcs if int(s.get("func_type", 0)) == 1])
    except ModalError:
        raise
    except (KeyError, TypeError, ValueError) as exc:   # a field missing or of the wrong form
        raise ModalError(f"{p}: dataset 58 record not understood ({type(exc).__name__}: {exc})") from None
    raise ModalError(f"{p}: dataset 58 function types {kinds} are not supported: none is an FRF (4) or a "
                     "time response (1)")


def _frf_outputs(p: Path, funcs: list[dict]) -> list[str]:
    """The response channel of each FRF: ``<node><sign><axis>``, with ``#k`` when several FRFs share a
    response and a reference: sensors told apart by their ID lines, or (direction code 0: skewed or
    tri-axial sensors) by their order; other repeats are refused (a file written twice over)."""
    outs = [channel_name(s["rsp_node"], s["rsp_dir"]) for s in funcs]
    pairs = [(o, channel_name(s["ref_node"], s["ref_dir"])) for o, s in zip(outs, funcs, strict=True)]
    names = list(outs)
    for pair in dict.fromkeys(pairs):   # a loop over response/reference pairs
        recs = [k for k, q in enumerate(pairs) if q == pair]
        if len(recs) == 1:
            continue
        number = _by_id([funcs[k] for k in recs])
        if len(set(number)) < len(recs):
            if int(funcs[recs[0]]["rsp_dir"]) != 0:
                raise ModalError(f"{p}: two FRFs for response {pair[0]} and reference {pair[1]} with the "
                                 "same ID line (one per pair is read; sensors sharing a node and direction "
                                 "need direction code 0 or different ID lines)")
            number = list(range(1, len(recs) + 1))
        for k, n in zip(recs, number, strict=True):
            names[k] = f"{pair[0]}#{n}"
    return names


def _frfs(p: Path, funcs: list[dict]) -> UffFrfs:
    x = np.asarray(funcs[0]["x"], float)
    names = _frf_outputs(p, funcs)
    outs, ins = [], []
    for o, s in zip(names, funcs, strict=True):
        if np.asarray(s["x"]).shape != x.shape or not np.allclose(s["x"], x):
            raise ModalError(f"{p}: FRF {o} has a different frequency axis")
        if not np.iscomplexobj(s["data"]):   # a magnitude export: "no stable poles" said nothing of it
            raise ModalError(f"{p}: FRF {o} holds real values (ordinate data type {s.get('ord_data_type')}), "
                             "no phase: FRFs are complex (H = X / F); export them as complex (type 5 or 6)")
        i = channel_name(s["ref_node"], s["ref_dir"])
        outs += [o] if o not in outs else []
        ins += [i] if i not in ins else []
    units = [_ordinate_units(s) for s in funcs]
    scale = _family_factors([u for u, _ in units])
    per_force = _family_factors([u for _, u in units])
    if per_force is not None:
        scale = (1.0 if scale is None else scale) / per_force
    H = np.full((len(outs), len(ins), x.size), np.nan, complex)
    for k, (o, s) in enumerate(zip(names, funcs, strict=True)):   # a loop over FRFs
        H[outs.index(o), ins.index(channel_name(s["ref_node"], s["ref_dir"]))] = \
            np.asarray(s["data"]) * (1.0 if scale is None else scale[k])
    if np.isnan(H).any():
        j, i = np.argwhere(np.isnan(H[..., 0]))[0]
        raise ModalError(f"{p}: the FRF matrix is incomplete: no FRF for response {outs[j]} and reference "
                         f"{ins[i]}")
    quantity = _quantity(p, funcs, names)
    found = {float(m.group(1)) for s in funcs for k in ("id2", "id3", "id4", "id5")
             if (m := _DECAY.search(str(s.get(k) or "")))}
    return UffFrfs(x, H, tuple(outs), tuple(ins), quantity, found.pop() if len(found) == 1 else 0.0)


_TYPE_UNITS = {8: "m", 11: "m/s", 12: "m/s^2", 13: "N"}   # SI unit of a UFF specific data type


def _label(record: dict, field: str) -> str | None:
    """A unit label of a record, None when it gives none (empty or pyuff's 'NONE')."""
    text = str(record.get(field) or "").strip()
    return None if text.upper() in ("", "NONE") else text


def _ordinate_units(record: dict) -> tuple[str, str]:
    """(numerator, denominator) unit of a dataset-58 record: its axis unit labels (a ratio label such as
    ``g/N`` or ``(m/s^2)/N`` split), else the SI unit of its data types (UFF data are SI unless a
    dataset 164 says otherwise, which :func:`_check_units` refuses): m/s^2 over N for an FRF."""
    from flexmodal.modal.sources import quantity_of

    num, den = _label(record, "ordinate_axis_units_lab"), _label(record, "orddenom_axis_units_lab")
    if num and den is None and "/" in num:
        head, _, tail = num.rpartition("/")
        if quantity_of(tail.strip()) == "force":
            num, den = head.strip().removeprefix("(").removesuffix(")").strip(), tail.strip()
    code = int(record.get("ordinate_spec_data_type", 12) or 12)
    return num or _TYPE_UNITS.get(code, "m/s^2"), den or "N"


def _family_factors(units: Sequence[str]) -> np.ndarray | None:
    """Factors [n] bringing records given in ``units`` to the SI unit of their quantity where the records
    of one quantity differ in unit (g beside m/s^2, kN beside N: modal.sources.si_factors, as for a
    run's channels); None when no quantity's records differ.  Records of different quantities (laser
    velocities beside reference accelerations in an output-only record, a real case) or of a unit with
    no known factor are kept as given."""
    from flexmodal.modal.sources import quantity_of, si_factors

    quantities = [quantity_of(u) for u in units]
    factors = np.ones(len(units))
    for quantity in set(quantities) - {None}:
        members = [k for k, q in enumerate(quantities) if q == quantity]
        scale = si_factors([units[k] for k in members])
        factors[members] = 1.0 if scale is None else scale
    return None if np.all(factors == 1.0) else factors


def _check_units(p: Path, units: list[dict]) -> None:
    """Refuse a units dataset (164) whose length or force factor is not 1: the data are then in other
    units than SI (mm, lbf), which were read as metres and newtons without a word (a factor of 0 or
    NaN is no unit at all)."""
    for u in units:
        factors = {k: u.get(k) for k in ("length", "force")}
        bad = {k: v for k, v in factors.items() if not isinstance(v, int | float) or not v == 1.0}
        if bad:
            k, v = next(iter(bad.items()))
            raise ModalError(f"{p}: dataset 164 gives units {str(u.get('units_description', '')).strip()!r} "
                             f"with {k} factor {v!r}: flexmodal reads SI data only (metre and newton, factor "
                             "1); convert the file to SI")


def _quantity(p: Path, funcs: list[dict], names: list[str]) -> str:
    """What the FRFs are, from their ordinate (numerator) data type: 8 receptance, 11 mobility,
    12 accelerance; 0 (unknown) and 1 (general), which some writers use for any FRF, are read as
    accelerance.  Any other code (a stress, a force, no code of the table at all) or FRFs of two
    different quantities are refused: they were read as accelerance without a word."""
    codes = []
    for name, s in zip(names, funcs, strict=True):
        code = s.get("ordinate_spec_data_type", 12)
        if code not in (0, 1, *_QUANTITY):
            raise ModalError(f"{p}: FRF {name}: ordinate data type {code!r} is not a response of an FRF "
                             "(8 displacement, 11 velocity, 12 acceleration; 0 unknown)")
        codes.append(_QUANTITY.get(int(code), "accelerance"))
    if len(set(codes)) > 1:
        raise ModalError(f"{p}: the FRFs mix {' and '.join(sorted(set(codes)))}; give them one quantity")
    return codes[0]


def _record_key(records: list[dict]) -> list:
    """How the records of one channel are told apart: their load case ids, else version (record)
    numbers, else function ids when those differ, else their order in the file."""
    for field in ("load_case_id", "ver_num", "func_id"):
        values = [r.get(field) for r in records]
        if None not in values and len(set(values)) == len(values):
            return values
    return list(range(len(records)))


def _split(funcs: list[dict], base: list[str], sensor) -> list[str]:
    """``base`` names with ``#k`` appended where ``sensor(records of one name)`` numbers more than one
    sensor (1-based, one number per record)."""
    names = list(base)
    for name in dict.fromkeys(base):   # a loop over nodes and directions
        recs = [k for k, b in enumerate(base) if b == name]
        number = sensor([funcs[k] for k in recs])
        if len(set(number)) > 1:
            for k, n in zip(recs, number, strict=True):
                names[k] = f"{name}#{n}"
    return names


def _by_case(recs: list[dict]) -> list[int]:
    """Response records of a node and direction sharing a load case (load case id, record number and
    function id alike) are different sensors: numbered by their ID line when those tell them apart,
    else by their order within the load case (forces are not split: one hammer or shaker per point)."""
    if any(_is_force(r) for r in recs):
        return [1] * len(recs)
    cases = [tuple(str(r.get(field)) for field in ("load_case_id", "ver_num", "func_id")) for r in recs]
    ids = _by_id(recs)
    by_id = all(len({i for i, c in zip(ids, cases, strict=True) if c == case}) == cases.count(case)
                for case in set(cases))
    if by_id and len(set(ids)) == max(cases.count(case) for case in cases):
        return ids
    seen: dict[tuple, int] = {}
    out = []
    for case in cases:   # a loop over records
        seen[case] = seen.get(case, 0) + 1
        out.append(seen[case])
    return out


def _is_force(record: dict) -> bool:
    return int(record.get("ordinate_spec_data_type", 12)) == 13


def _by_id(recs: list[dict]) -> list[int]:
    """Records of a node and direction with different ID lines are different sensors."""
    ids = [str(r.get("id1", "")).strip() for r in recs]
    order = list(dict.fromkeys(ids))
    return [order.index(i) + 1 for i in ids]


def _channel_names(funcs: list[dict]) -> list[str]:
    """The channel of each time-history record: ``<node><sign><axis>`` from its node and direction;
    when several sensors share a node and direction (direction code 0: skewed or tri-axial sensors)
    their records are told apart, ``#k`` after the name, by the first reading that gives every channel
    the same number of records: response records sharing a load case (the k-th of each is sensor k),
    none (records told apart by load case, record number, function id or order are hits of one
    channel), records with different ID lines, or every record its own sensor."""
    base = [channel_name(s["rsp_node"], s["rsp_dir"]) for s in funcs]
    readings = [_split(funcs, base, _by_case), base, _split(funcs, base, _by_id),
                _split(funcs, base, lambda recs: list(range(1, len(recs) + 1)))]
    for names in readings:   # a loop over four readings
        counts = {n: names.count(n) for n in names}
        if len(set(counts.values())) == 1:
            return names
    return base


def _record(p: Path, funcs: list[dict]) -> UffRecord:
    dts = np.array([float(s.get("abscissa_inc") or np.diff(s["x"][:2])[0]) for s in funcs])
    if not np.all(dts > 0):
        raise ModalError(f"{p}: a time history has no positive sample interval ({dts.min():g} s)")
    if dts.min() < 1 / MAX_SAMPLE_RATE_HZ:   # 1e-300 s: a rate that overflows the spectra's arithmetic
        raise ModalError(f"{p}: time histories sampled every {dts.min():.3g} s, a rate above "
                         f"{MAX_SAMPLE_RATE_HZ:g} Hz; is the abscissa in seconds?")
    if not np.allclose(dts, dts[0], rtol=1e-9):
        raise ModalError(f"{p}: time histories have mismatched sample rates "
                         f"({', '.join(f'{1 / d:g}' for d in sorted(set(dts)))} Hz)")
    channels: dict[str, list[dict]] = {}
    for name, s in zip(_channel_names(funcs), funcs, strict=True):   # a loop over records
        channels.setdefault(name, []).append(s)
    names = tuple(channels)
    kinds = tuple("force" if _is_force(recs[0]) else "acceleration" for recs in channels.values())
    counts = {n: len(r) for n, r in channels.items()}
    if len(set(counts.values())) != 1:
        raise ModalError(f"{p}: channels hold different numbers of records ("
                         + ", ".join(f"{n}: {c}" for n, c in counts.items()) + ")")
    scale = _family_factors([_ordinate_units(recs[0])[0] for recs in channels.values()])
    factors = np.ones(len(names)) if scale is None else scale
    if counts[names[0]] == 1:
        lengths = {len(r[0]["data"]) for r in channels.values()}
        if len(lengths) != 1:
            raise ModalError(f"{p}: time histories have different lengths {sorted(lengths)}")
        samples = np.column_stack([np.asarray(r[0]["data"], float) for r in channels.values()])
        return UffRecord(samples * factors, 1.0 / dts[0], names, kinds)
    hits = _hits(p, channels, names, kinds, 1.0 / dts[0])
    return hits if np.all(factors == 1.0) else dataclasses.replace(hits, samples=hits.samples * factors)


def _hits(p: Path, channels: dict[str, list[dict]], names: tuple[str, ...], kinds: tuple[str, ...],
          fs: float) -> UffRecord:
    """Several records per channel: record k of every channel (matched by load case, record number
    or order) is hit k; hits are cut to the shortest record and laid end to end."""
    from flexmodal.modal.impact import find_triggers

    keys = [_record_key(r) for r in channels.values()]
    order = sorted(keys[0], key=str)
    odd = [n for n, k in zip(names, keys, strict=True) if sorted(k, key=str) != order]
    if odd:
        raise ModalError(f"{p}: channels {names[0]} and {odd[0]} hold records of different load cases "
                         "or record numbers")
    hits = [[recs[k.index(key)] for recs, k in zip(channels.values(), keys, strict=True)] for key in order]
    length = min(len(r["data"]) for hit in hits for r in hit)
    samples = np.concatenate([np.column_stack([np.asarray(r["data"], float)[:length] for r in hit])
                              for hit in hits])
    if "force" not in kinds:
        return UffRecord(samples, fs, names, kinds, length)
    f = kinds.index("force")
    first = [find_triggers(samples[k * length:(k + 1) * length, f]) for k in range(len(hits))]
    triggers = tuple(int(k * length + t[0]) for k, t in enumerate(first) if t.size)
    return UffRecord(samples, fs, names, kinds, length, triggers)


def write_frfs(path: str | Path, result: FrfResult) -> None:
    """Write FRFs as dataset 58 (function type 4), one set per response/reference pair; the decay
    rate of an exponential window they were measured with goes into id line 4 ("exponential window
    decay R 1/s"), where :func:`read_uff` finds it again (other tools keep id lines as text)."""
    import pyuff

    note = (f"exponential window decay {result.decay_rate_per_s:.9g} 1/s" if result.decay_rate_per_s
            else "NONE")
    sets = []
    for o, oname in enumerate(result.outputs or [f"{k + 1}+z" for k in range(result.H.shape[0])]):
        for i, iname in enumerate(result.inputs or [f"{900 + k}+z" for k in range(result.H.shape[1])]):
            rn, rd = _node_dir(oname, o + 1)
            fn, fd = _node_dir(iname, 900 + i)
            sets.append(pyuff.prepare_58(
                func_type=4, id1=f"FRF {oname}/{iname}", id4=note, rsp_node=rn, rsp_dir=rd, ref_node=fn,
                ref_dir=fd,
                ordinate_spec_data_type=_SPEC.get(result.quantity, 12), orddenom_spec_data_type=13,
                abscissa_spec_data_type=18, data=np.asarray(result.H[o, i], complex),
                x=np.asarray(result.freq_hz, float), abscissa_spacing=1,
                abscissa_min=float(result.freq_hz[0]),
                abscissa_inc=float(result.freq_hz[1] - result.freq_hz[0]), num_pts=len(result.freq_hz)))
    with atomic_path(path) as tmp:
        pyuff.UFF(str(tmp)).write_sets(sets, mode="overwrite")


def write_modes(path: str | Path, freq_hz: Sequence[float], damping_ratio: Sequence[float],
                shapes: np.ndarray, outputs: Sequence[str]) -> None:
    """Write real mode shapes [n_out, n_modes] as dataset 55 (normal modes, one set per mode)."""
    import pyuff

    nodes = [_node_dir(name, k + 1) for k, name in enumerate(outputs)]
    node_ids = sorted({n for n, _ in nodes})
    sets = []
    for r, (fn, zeta) in enumerate(zip(freq_hz, damping_ratio, strict=True)):
        comp = np.zeros((len(node_ids), 3))
        for (n, d), value in zip(nodes, shapes[:, r], strict=True):
            comp[node_ids.index(n), abs(d) - 1] += np.sign(d) * float(np.real(value))
        sets.append(pyuff.prepare_55(
            id1=f"mode {r + 1}", model_type=1, analysis_type=2, data_ch=2, spec_data_type=8, data_type=2,
            n_data_per_node=3, load_case=1, mode_n=r + 1, freq=float(fn), modal_m=0.0,
            modal_damp_vis=float(zeta),
            modal_damp_his=0.0, node_nums=np.array(node_ids), r1=comp[:, 0], r2=comp[:, 1], r3=comp[:, 2]))
    with atomic_path(path) as tmp:
        pyuff.UFF(str(tmp)).write_sets(sets, mode="overwrite")
