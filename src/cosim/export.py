"""Fields of structures over time, for ParaView (meshio XDMF, XML data)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["export_structures"]


def export_structures(scene, result, out_dir) -> list[Path]:
    """Write ``OUT/NAME.xdmf`` for each structure the scene lists in
    ``output.export``: the nodes, line cells, and per recorded time the
    field ``w`` and the displacement vector (padded to 3 components).

    meshio is imported here only, so runs that export nothing never load it.
    """
    names = scene.export
    if not names:
        return []
    import meshio

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    specs = {s["name"]: s for s in scene.subsystems}
    t = result.t
    for name in names:
        structure = specs[name]["model"].assemble()
        nodes = structure.nodes()
        U = np.column_stack([result.series[f"q/{name}/{d}"] for d in structure.dof_names])
        W = structure.nodal_displacement(U)                      # (T, N)
        cells = [("line", np.column_stack([np.arange(len(nodes) - 1),
                                           np.arange(1, len(nodes))]))]
        direction = np.asarray(structure.direction, float)
        path = out / f"{name}.xdmf"
        fd, tmp = tempfile.mkstemp(dir=out, prefix=f".{name}.", suffix=".xdmf")
        os.close(fd)
        try:
            with meshio.xdmf.TimeSeriesWriter(tmp, data_format="XML") as writer:
                writer.write_points_cells(nodes, cells)
                for k in range(0, len(t), scene.export_every):
                    disp = np.zeros((len(nodes), 3))
                    disp[:, :2] = W[k][:, None] * direction
                    writer.write_data(float(t[k]), point_data={"w": W[k],
                                                               "displacement": disp})
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        written.append(path)
    return written
