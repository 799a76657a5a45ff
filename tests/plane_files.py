"""A plane mesh built in code (fem.plane.rectangle) written as a Gmsh 2.2
file with its groups, for scenes made at test time."""
import numpy as np


def write_msh(path, mesh, name="body"):
    """Write ``mesh`` (a :class:`fem.plane.PlaneMesh`) to ``path`` with its
    curve groups as physical curves and its cells as one physical surface."""
    import meshio
    tags = {g: i + 1 for i, g in enumerate(sorted(mesh.groups))}
    lines = np.concatenate([mesh.groups[g] for g in tags])
    phys = np.concatenate([np.full(len(mesh.groups[g]), t) for g, t in tags.items()])
    kind = "triangle" if mesh.cells.shape[1] == 3 else "quad"
    surface = len(tags) + 1
    meshio.write(path, meshio.Mesh(
        np.c_[mesh.points, np.zeros(len(mesh.points))],
        [meshio.CellBlock("line", lines), meshio.CellBlock(kind, mesh.cells)],
        cell_data={"gmsh:physical": [phys, np.full(len(mesh.cells), surface)],
                   "gmsh:geometrical": [phys, np.full(len(mesh.cells), 1)]},
        field_data={**{g: np.array([t, 1]) for g, t in tags.items()},
                    name: np.array([surface, 2])}), file_format="gmsh22", binary=False)
    return path


def spy_kernels(monkeypatch) -> list:
    """The structure kernels built from now on (``None`` where a side had
    none), appended as :meth:`StructureSubsystem._build_kernel` makes them."""
    from cosim.sides.fem import StructureSubsystem
    built = []
    original = StructureSubsystem._build_kernel

    def spy(self):
        k = original(self)
        built.append(k)
        return k

    monkeypatch.setattr(StructureSubsystem, "_build_kernel", spy)
    return built
