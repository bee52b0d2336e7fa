"""Universal File Format interchange through pyuff (dataset 58: functions at nodes; dataset 55: mode
shapes), so FRFs and modes open in ME'scope, Simcenter Testlab and similar tools.

Read: dataset 58 of function type 4 (FRF) or 1 (time response; the force channels are those whose
ordinate is a force, data type 13).  Channels are named ``<node><sign><axis>`` (e.g. ``3+z``) from
the node and direction codes.  Write: FRFs as dataset 58 type 4, modes as dataset 55 (real, three
components per node, the shape value in the channel's direction)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.valid_uff import check_functions

_AXES = "xyz"
_SPEC = {"accelerance": 12, "mobility": 11, "receptance": 8}
_QUANTITY = {v: k for k, v in _SPEC.items()}


def channel_name(node: int, direction: int) -> str:
    d = int(direction)
    if 1 <= abs(d) <= 3:
        return f"{int(node)}{'+' if d > 0 else '-'}{_AXES[abs(d) - 1]}"
    return f"{int(node)}:{d}"


def _node_dir(name: str, default_node: int) -> tuple[int, int]:
    if len(name) >= 3 and name[-2] in "+-" and name[-1] in _AXES and name[:-2].isdigit():
        return int(name[:-2]), (1 if name[-2] == "+" else -1) * (_AXES.index(name[-1]) + 1)
    return default_node, 3


@dataclass(frozen=True)
class UffFrfs:
    freq_hz: np.ndarray
    H: np.ndarray
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    quantity: str


@dataclass(frozen=True)
class UffRecord:
    samples: np.ndarray
    sample_rate_hz: float
    names: tuple[str, ...]
    kinds: tuple[str, ...]


def read_uff(path: str | Path) -> UffFrfs | UffRecord:
    """FRFs (type 4) or a time record (type 1) from the dataset-58 sets of a UFF file."""
    import pyuff

    p = Path(path)
    if not p.is_file():
        raise ModalError(f"{p}: UFF file not found")
    try:
        sets = pyuff.UFF(str(p)).read_sets()
    except Exception as exc:  # pyuff raises bare Exceptions on malformed files
        raise ModalError(f"{p}: not a readable UFF file ({exc})") from None
    sets = [sets] if isinstance(sets, dict) else list(sets)
    types = sorted({int(s.get("type", -1)) for s in sets})
    funcs = [s for s in sets if s.get("type") == 58]
    if not funcs:
        raise ModalError(f"{p}: no dataset 58 (found dataset types {types}; only 58 is read)")
    check_functions(p, funcs)
    kinds = sorted({int(s.get("func_type", 0)) for s in funcs})
    if kinds not in ([1], [4]):
        raise ModalError(f"{p}: dataset 58 function types {kinds} are not supported "
                         "(use all 4 = FRF or all 1 = time response)")
    if kinds == [4]:
        return _frfs(p, funcs)
    return _record(p, funcs)


def _frfs(p: Path, funcs: list[dict]) -> UffFrfs:
    x = np.asarray(funcs[0]["x"], float)
    outs, ins = [], []
    for s in funcs:
        if np.asarray(s["x"]).shape != x.shape or not np.allclose(s["x"], x):
            raise ModalError(f"{p}: FRF {channel_name(s['rsp_node'], s['rsp_dir'])} has a different "
                             "frequency axis")
        o, i = channel_name(s["rsp_node"], s["rsp_dir"]), channel_name(s["ref_node"], s["ref_dir"])
        outs += [o] if o not in outs else []
        ins += [i] if i not in ins else []
    H = np.full((len(outs), len(ins), x.size), np.nan, complex)
    for s in funcs:
        H[outs.index(channel_name(s["rsp_node"], s["rsp_dir"])),
          ins.index(channel_name(s["ref_node"], s["ref_dir"]))] = np.asarray(s["data"])
    if np.isnan(H).any():
        raise ModalError(f"{p}: the FRF matrix is incomplete (some response/reference pairs missing)")
    quantity = _QUANTITY.get(int(funcs[0].get("ordinate_spec_data_type", 12)), "accelerance")
    return UffFrfs(x, H, tuple(outs), tuple(ins), quantity)


def _record(p: Path, funcs: list[dict]) -> UffRecord:
    dts = np.array([float(s.get("abscissa_inc") or np.diff(s["x"][:2])[0]) for s in funcs])
    if not np.allclose(dts, dts[0], rtol=1e-9):
        raise ModalError(f"{p}: time histories have mismatched sample rates "
                         f"({', '.join(f'{1 / d:g}' for d in sorted(set(dts)))} Hz)")
    lengths = {len(s["data"]) for s in funcs}
    if len(lengths) != 1:
        raise ModalError(f"{p}: time histories have different lengths {sorted(lengths)}")
    samples = np.column_stack([np.asarray(s["data"], float) for s in funcs])
    names = tuple(channel_name(s["rsp_node"], s["rsp_dir"]) for s in funcs)
    kinds = tuple("force" if int(s.get("ordinate_spec_data_type", 12)) == 13 else "acceleration"
                  for s in funcs)
    return UffRecord(samples, 1.0 / dts[0], names, kinds)


def write_frfs(path: str | Path, result: FrfResult) -> None:
    """Write FRFs as dataset 58 (function type 4), one set per response/reference pair."""
    import pyuff

    sets = []
    for o, oname in enumerate(result.outputs or [f"{k + 1}+z" for k in range(result.H.shape[0])]):
        for i, iname in enumerate(result.inputs or [f"{900 + k}+z" for k in range(result.H.shape[1])]):
            rn, rd = _node_dir(oname, o + 1)
            fn, fd = _node_dir(iname, 900 + i)
            sets.append(pyuff.prepare_58(
                func_type=4, id1=f"FRF {oname}/{iname}", rsp_node=rn, rsp_dir=rd, ref_node=fn, ref_dir=fd,
                ordinate_spec_data_type=_SPEC.get(result.quantity, 12), orddenom_spec_data_type=13,
                abscissa_spec_data_type=18, data=np.asarray(result.H[o, i], complex),
                x=np.asarray(result.freq_hz, float), abscissa_spacing=1,
                abscissa_min=float(result.freq_hz[0]),
                abscissa_inc=float(result.freq_hz[1] - result.freq_hz[0]), num_pts=len(result.freq_hz)))
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")


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
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
