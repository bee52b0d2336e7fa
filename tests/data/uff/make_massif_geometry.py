"""Writes massif_geometry.uff (run by hand; tests read the committed file).

Geometry: the six nodes of the part "Massif" of pyuff's sample ``data/TestLab 161 164 18 15 82.uff``
(https://github.com/ladisk/pyuff, MIT licence; a Simcenter Testlab export): their coordinates
(dataset 15), their displacement coordinate systems (dataset 18: origin, a point on the local x axis
and one in the local xz plane; local z points down, global -z) and the part's trace line (dataset 82),
retyped here.  FRFs (dataset 58, accelerance, (m/s²)/N) at every node in local +z for a force at node
3 in local +z, synthesised from two known modes in global z (12 Hz, 2 %: bounce with a slope along y;
31 Hz, 1.5 %: roll about y), so a test knows the shapes to expect.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyuff

NODES = np.array([1, 2, 3, 4, 5, 6])
XYZ = np.array([[-2.4, -0.95, 0.0], [-2.6, 2.05, 0.0], [2.6, 2.05, 0.0], [2.4, -0.95, 0.0],
                [-1.2, 8.35, 0.0], [1.2, 8.35, 0.0]])
TRACE = [2, 5, 6, 3, 4, 1, 2, 3]
MODES_HZ = (12.0, 31.0)
DAMPING = (0.02, 0.015)
INPUT_NODE = 3


def global_z_shapes() -> np.ndarray:
    """Mode shapes [6 nodes, 2 modes] in global z."""
    x, y = XYZ[:, 0], XYZ[:, 1]
    return np.column_stack([1.0 + 0.05 * y, x / 2.6])


def write(path: Path) -> None:
    f = np.linspace(0.0, 60.0, 241)
    w = 2 * np.pi * f
    phi = -global_z_shapes()                       # local +z is global -z at every node
    ref = phi[INPUT_NODE - 1]
    wr = 2 * np.pi * np.array(MODES_HZ)
    recept = sum(np.outer(phi[:, r], [ref[r]])[:, :, None]
                 / (wr[r] ** 2 - w ** 2 + 2j * DAMPING[r] * wr[r] * w) for r in range(2))[:, 0, :]
    accel = -(w ** 2) * recept
    sets = [pyuff.prepare_18(cs_num=NODES.astype(float), cs_type=np.zeros(6), ref_cs_num=np.zeros(6),
                             color=np.full(6, 8.0), method=np.ones(6), cs_name=[f"SYS{n}" for n in NODES],
                             ref_o=XYZ, x_point=XYZ + [-1.0, 0.0, 0.0], xz_point=XYZ + [-1.0, 0.0, -1.0]),
            pyuff.prepare_15(node_nums=NODES.tolist(), def_cs=[0] * 6, disp_cs=NODES.tolist(), color=[8] * 6,
                             x=XYZ[:, 0].tolist(), y=XYZ[:, 1].tolist(), z=XYZ[:, 2].tolist()),
            pyuff.prepare_82(trace_num=1, n_nodes=len(TRACE), color=8, id="Massif", nodes=np.array(TRACE))]
    for k, node in enumerate(NODES):
        sets.append(pyuff.prepare_58(
            binary=0, id1="FRF", id2=f"massif {node}+z / {INPUT_NODE}+z", id3="two known modes", id4="none",
            id5="none", func_type=4, ver_num=1, load_case_id=1, rsp_ent_name="Massif", rsp_node=int(node),
            rsp_dir=3, ref_ent_name="Massif", ref_node=INPUT_NODE, ref_dir=3, ord_data_type=5, num_pts=f.size,
            abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=float(f[1] - f[0]), abscissa_spec_data_type=18,
            ordinate_spec_data_type=12, orddenom_spec_data_type=13, x=f, data=accel[k]))
    path.unlink(missing_ok=True)
    uff = pyuff.UFF(str(path))
    for s in sets:
        uff.write_sets(s, mode="add")


if __name__ == "__main__":
    write(Path(__file__).with_name("massif_geometry.uff"))
