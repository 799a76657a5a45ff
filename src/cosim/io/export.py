"""Fields of structures over time, for ParaView (meshio XDMF, XML data)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from cosim.io.rundir import inside, output_error

__all__ = ["export_structures"]


def export_structures(scene, result, out_dir) -> list[Path]:
    """Write ``OUT/NAME.xdmf`` for each structure the scene lists in
    ``output.export``: the nodes, line cells, and per recorded time the
    field ``w`` and the displacement vector (padded to 3 components).

    Each file is written under a new temporary name in ``OUT`` and moved into
    place whole; its path is checked to lie in ``OUT``
    (:func:`cosim.io.rundir.inside`).  An :class:`OSError` becomes a
    :class:`cosim.errors.OutputError` naming the file.

    meshio is imported here only, so runs that export nothing never load it.
    """
    names = scene.export
    if not names:
        return []
    import meshio

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_error(exc, out, "cannot make the run folder") from exc
    written = []
    specs = {s.name: s for s in scene.subsystems}
    t = result.t
    for name in names:
        structure = specs[name].model.assemble()
        nodes = structure.nodes()
        U = np.column_stack([result.series[f"q/{name}/{d}"] for d in structure.dof_names])
        W = structure.nodal_displacement(U)                      # (T, N)
        cells = [("line", np.column_stack([np.arange(len(nodes) - 1),
                                           np.arange(1, len(nodes))]))]
        direction = np.asarray(structure.direction, float)
        path = inside(out, f"{name}.xdmf")
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(dir=out, prefix=f".{name}.", suffix=".xdmf")
            os.close(fd)
            with meshio.xdmf.TimeSeriesWriter(tmp, data_format="XML") as writer:
                writer.write_points_cells(nodes, cells)
                for k in range(0, len(t), scene.export_every):
                    disp = np.zeros((len(nodes), 3))
                    disp[:, :2] = W[k][:, None] * direction
                    writer.write_data(float(t[k]), point_data={"w": W[k],
                                                               "displacement": disp})
            os.replace(tmp, path)
        except BaseException as exc:
            if tmp is not None and os.path.lexists(tmp):
                os.unlink(tmp)
            if isinstance(exc, OSError):
                raise output_error(exc, path) from exc
            raise
        written.append(path)
    return written
