"""Fields of structures over time, for ParaView (meshio XDMF, XML data)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cosim.io.rundir import OutputFolder

__all__ = ["export_structures"]


def export_structures(scene, result, out_dir) -> list[Path]:
    """Write ``OUT/NAME.xdmf`` for each structure the scene lists in
    ``output.export``: the nodes, line cells, and per recorded time the
    field ``w`` and the displacement vector (padded to 3 components).

    Each file goes through the checked writer
    (:meth:`cosim.io.rundir.OutputFolder.write_by_path`): written in a new
    private temporary folder in ``OUT`` and moved into place whole, never
    through a link.  An :class:`OSError` becomes a
    :class:`cosim.errors.OutputError` naming the file.

    meshio is imported here only, so runs that export nothing never load it.
    """
    names = scene.export
    if not names:
        return []
    import meshio

    with OutputFolder(out_dir, lock=False) as folder:      # the run holds the lock
        return [_export(scene, result, folder, name, meshio) for name in names]


def _export(scene, result, folder, name, meshio) -> Path:
    """Write ``NAME.xdmf`` of the structure ``name`` into ``folder``."""
    specs = {s.name: s for s in scene.subsystems}
    t = result.t
    structure = specs[name].model.assemble()
    nodes = structure.nodes()
    U = np.column_stack([result.series[f"q/{name}/{d}"] for d in structure.dof_names])
    W = structure.nodal_displacement(U)                      # (T, N)
    cells = [("line", np.column_stack([np.arange(len(nodes) - 1),
                                       np.arange(1, len(nodes))]))]
    direction = np.asarray(structure.direction, float)

    def write(tmp):
        with meshio.xdmf.TimeSeriesWriter(tmp, data_format="XML") as writer:
            writer.write_points_cells(nodes, cells)
            for k in range(0, len(t), scene.export_every):
                disp = np.zeros((len(nodes), 3))
                disp[:, :2] = W[k][:, None] * direction
                writer.write_data(float(t[k]), point_data={"w": W[k],
                                                           "displacement": disp})
    return folder.write_by_path(f"{name}.xdmf", write)
