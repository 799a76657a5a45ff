"""Fields of structures over time, for ParaView (meshio XDMF, XML data).

A line structure (chain, beam, cable, string, rod) records its physical
DOFs; its file holds its nodes, line cells and per recorded time the field
``w`` and the displacement vector.  A plane body records its modal
coordinates only: its file holds the mesh's vertices and first-order cells
(triangles or quadrangles, world frame) and per recorded time the
displacement of every vertex, ``Phi q`` from the kept modes and the
recorded coordinates (ParaView's *Warp By Vector* on ``displacement`` draws
the deformed body).  The static correction a contact adds to the dropped
modes is a compliance of that contact, not a field, and is not in it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cosim.io.rundir import OutputFolder

__all__ = ["export_structures", "plane_fields"]


def export_structures(scene, result, out_dir, system=None) -> list[Path]:
    """Write ``OUT/NAME.xdmf`` for each structure the scene lists in
    ``output.export``: the nodes, line cells, and per recorded time the
    field ``w`` and the displacement vector (padded to 3 components).

    Each file goes through the checked writer
    (:meth:`cosim.io.rundir.OutputFolder.write_by_path`): written in a new
    private temporary folder in ``OUT`` and moved into place whole, never
    through a link.  An :class:`OSError` becomes a
    :class:`cosim.errors.OutputError` naming the file.

    ``system`` is the system that ran (its plane bodies' modes give their
    fields); without it a plane body's subsystem is built again from the
    scene (the modes are the same: a fixed start vector, or the cache).

    meshio is imported here only, so runs that export nothing never load it.
    """
    names = scene.export
    if not names:
        return []
    import meshio

    with OutputFolder(out_dir, lock=False) as folder:      # the run holds the lock
        return [_export(scene, result, folder, name, meshio, system) for name in names]


def _plane_subsystem(scene, name, system):
    if system is None:
        system, _ = scene.build()
    return next(s for s in system.subsystems if s.name == name)


def plane_fields(sub, result, every: int = 1):
    """The recorded times (every ``every``-th) and the displacement of every
    vertex of the plane body ``sub`` (a :class:`~cosim.sides.plane.PlaneSubsystem`)
    there: ``t`` (T,), ``U`` (T, N, 2) [m], world frame, ``Phi q``."""
    t = np.asarray(result.t)[::every]
    q = np.column_stack([np.asarray(result.series[f"q/{sub.name}/mode{i + 1}"])[::every]
                         for i in range(sub.n_modes)])
    return t, sub.field(q)


def _export_plane(scene, result, folder, name, meshio, system) -> Path:
    sub = _plane_subsystem(scene, name, system)
    structure = sub.structure
    nodes = structure.nodes()
    points = np.zeros((len(nodes), 3))
    points[:, :2] = nodes
    cells = [(structure.mesh.kind, np.asarray(structure.mesh.cells))]
    t, U = plane_fields(sub, result, scene.export_every)

    def write(tmp):
        with meshio.xdmf.TimeSeriesWriter(tmp, data_format="XML") as writer:
            writer.write_points_cells(points, cells)
            for k in range(len(t)):
                disp = np.zeros((len(nodes), 3))
                disp[:, :2] = U[k]
                writer.write_data(float(t[k]), point_data={"displacement": disp})
    return folder.write_by_path(f"{name}.xdmf", write)


def _export(scene, result, folder, name, meshio, system=None) -> Path:
    """Write ``NAME.xdmf`` of the structure ``name`` into ``folder``."""
    specs = {s.name: s for s in scene.subsystems}
    if specs[name].type == "plane":
        return _export_plane(scene, result, folder, name, meshio, system)
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
