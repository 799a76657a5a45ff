"""A plane body's mesh: read through meshio with its named boundary groups,
and every trap of the pipeline refused with a message that names the file
and the fix."""
from pathlib import Path

import numpy as np
import pytest

from fem.plane import MeshError, Plane, PlaneMesh, dof_count, read_mesh, rectangle

DATA = Path(__file__).parent / "data"
STEEL = dict(thickness=0.01, youngs_modulus=210e9, poisson_ratio=0.3, density=7850.0)


def _write(path, points, blocks, physical=None, names=None, fmt="gmsh22"):
    """A mesh file: ``blocks`` of (cell type, cells), Gmsh physical tags per block."""
    import meshio
    cells = [meshio.CellBlock(t, np.asarray(c)) for t, c in blocks]
    data = {}
    if physical is not None:
        data = {"gmsh:physical": [np.asarray(p) for p in physical],
                "gmsh:geometrical": [np.ones(len(c), dtype=int) for _, c in blocks]}
    meshio.write(path, meshio.Mesh(np.asarray(points, float), cells, cell_data=data,
                                   field_data=names or {}), file_format=fmt, binary=False)
    return path


SQUARE = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
TRIS = [[0, 1, 2], [0, 2, 3]]


def _refused(path, *words, **kw):
    with pytest.raises(MeshError) as info:
        read_mesh(path, **kw)
    msg = str(info.value)
    assert str(path) in msg
    for w in words:
        assert w in msg, msg
    return msg


# ---------------------------------------------------------------------------
# The committed Gmsh 4.1 file read back with its groups
# ---------------------------------------------------------------------------
def test_the_gmsh_41_plate_is_read_back_with_its_groups_in_metres():
    mesh = read_mesh(DATA / "plate.msh", scale=1e-3)
    assert mesh.kind == "triangle" and mesh.cells.shape == (32, 3)
    assert sorted(mesh.groups) == ["clamp", "face", "tip"]     # bottom is in no group
    assert np.allclose(np.ptp(mesh.points, axis=0), [0.2, 0.05])
    p = mesh.points
    assert np.allclose(p[mesh.groups["clamp"]][..., 0], 0.0)
    assert np.allclose(p[mesh.groups["tip"]][..., 0], 0.2)
    assert np.allclose(p[mesh.groups["face"]][..., 1], 0.05)
    assert mesh.groups["face"].shape == (8, 2)
    st = Plane(DATA / "plate.msh", scale=1e-3, fixed="clamp", **STEEL).assemble()
    # the top curve runs right to left in the file: its arc length starts at x = 0.2
    pt = st.boundary_point("face", 0.01)
    assert np.allclose(pt.position, [0.19, 0.05]) and np.allclose(pt.normal, [0, 1])
    assert st.group_length("face") == pytest.approx(0.2, rel=1e-14)
    # every DOF on the clamped edge is gone: 3 nodes and 2 edge midpoints, 2 components
    assert st.n_dof == dof_count(mesh, "P2") - 2 * 5


def test_a_gmsh_22_file_carries_its_groups_too(tmp_path):
    m = rectangle(1.0, 0.1, 4, 1)
    lines = np.concatenate([m.groups["left"], m.groups["top"]])
    tags = [np.r_[np.full(1, 1), np.full(4, 2)], np.full(len(m.cells), 3)]
    path = _write(tmp_path / "strip.msh", np.c_[m.points, np.zeros(len(m.points))],
                  [("line", lines), ("triangle", m.cells)], tags,
                  {"wall": np.array([1, 1]), "skin": np.array([2, 1]),
                   "body": np.array([3, 2])})
    mesh = read_mesh(path)
    assert sorted(mesh.groups) == ["skin", "wall"]
    assert np.array_equal(mesh.groups["skin"], m.groups["top"])


# ---------------------------------------------------------------------------
# The traps
# ---------------------------------------------------------------------------
def test_curves_without_a_physical_surface_are_refused_with_the_fix(tmp_path):
    path = _write(tmp_path / "curves.msh", SQUARE, [("line", [[0, 1], [1, 2]])],
                  [[1, 1]], {"edge": np.array([1, 1])})
    _refused(path, "physical curves", "Physical Surface")


def test_a_file_without_2d_cells_is_refused(tmp_path):
    path = _write(tmp_path / "lines.msh", SQUARE, [("line", [[0, 1], [1, 2]])])
    _refused(path, "no 2-D cells", "Mesh 2")


def test_mixed_cells_are_refused(tmp_path):
    pts = SQUARE + [[2, 0, 0], [2, 1, 0]]
    path = _write(tmp_path / "mixed.msh", pts, [("triangle", TRIS), ("quad", [[1, 4, 5, 2]])])
    _refused(path, "mixes triangles and quadrangles", "RecombineAll")


def test_second_order_cells_are_refused(tmp_path):
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [.5, 0, 0], [.5, .5, 0], [0, .5, 0]]
    path = _write(tmp_path / "p2.msh", pts, [("triangle6", [[0, 1, 2, 3, 4, 5]])])
    _refused(path, "second-order", "ElementOrder = 1", "P2")


def test_3d_cells_are_refused(tmp_path):
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    path = _write(tmp_path / "tet.msh", pts, [("tetra", [[0, 1, 2, 3]])])
    _refused(path, "3-D cells")


def test_a_mesh_off_the_plane_z_0_is_refused(tmp_path):
    pts = [[0, 0, 0], [1, 0, 0], [1, 1, 0.2], [0, 1, 0]]
    path = _write(tmp_path / "tilted.msh", pts, [("triangle", TRIS)])
    _refused(path, "z is not zero", "z = 0")


def test_an_inverted_cell_is_refused_and_a_clockwise_surface_is_reversed(tmp_path):
    m = rectangle(1.0, 1.0, 3, 3)
    cells = m.cells.copy()
    cells[4] = cells[4][::-1]
    pts = np.c_[m.points, np.zeros(len(m.points))]
    path = _write(tmp_path / "tangled.msh", pts, [("triangle", cells)])
    _refused(path, "inverted", "Mesh.Optimize")
    path = _write(tmp_path / "clockwise.msh", pts, [("triangle", m.cells[:, ::-1])])
    assert np.array_equal(np.sort(read_mesh(path).cells, axis=1), np.sort(m.cells, axis=1))


def test_a_degenerate_cell_is_refused(tmp_path):
    pts = SQUARE + [[2, 0, 0]]
    path = _write(tmp_path / "flat.msh", pts, [("triangle", TRIS + [[0, 1, 4]])])
    _refused(path, "degenerate")


def test_missing_and_empty_groups_are_refused_by_name(tmp_path):
    path = _write(tmp_path / "sq.msh", SQUARE, [("line", [[0, 1]]), ("triangle", TRIS)],
                  [[1], [3, 3]], {"base": np.array([1, 1]), "ghost": np.array([2, 1]),
                                  "body": np.array([3, 2])})
    with pytest.raises(MeshError, match=r"no boundary group 'top' \(its groups: 'base', "
                                        r"'ghost'\)") as info:
        Plane(path, fixed="top", **STEEL).assemble()
    assert str(path) in str(info.value)
    with pytest.raises(MeshError, match="'ghost' holds no line cells") as info:
        Plane(path, fixed="ghost", **STEEL).assemble()
    assert str(path) in str(info.value)


def test_a_group_that_is_not_an_edge_of_the_cells_is_refused(tmp_path):
    path = _write(tmp_path / "diag.msh", SQUARE, [("line", [[1, 3]]), ("triangle", TRIS)],
                  [[1], [3, 3]], {"cut": np.array([1, 1]), "body": np.array([3, 2])})
    _refused(path, "'cut'", "not edges")


def test_the_dof_bound_is_checked_from_the_file_before_assembly(tmp_path):
    m = rectangle(1.0, 1.0, 10, 10)
    path = _write(tmp_path / "big.msh", np.c_[m.points, np.zeros(len(m.points))],
                  [("triangle", m.cells)])
    n_p2 = 2 * (121 + 320)                      # vertices and edges of 10 x 10 x 2 triangles
    assert dof_count(read_mesh(path), "P2") == n_p2
    _refused(path, f"{n_p2} degrees of freedom", "over the bound of 800", "P1", max_dof=800)
    assert dof_count(read_mesh(path, element="P1", max_dof=800), "P1") == 2 * 121


def test_an_element_that_does_not_fit_the_cells_is_refused(tmp_path):
    path = _write(tmp_path / "tri.msh", SQUARE, [("triangle", TRIS)])
    _refused(path, "'Q2' needs quad cells", "P1 or P2", element="Q2")


def test_an_unreadable_or_missing_file_is_refused(tmp_path):
    bad = tmp_path / "junk.msh"
    bad.write_text("$MeshFormat\nnot a mesh\n")
    _refused(bad, "meshio cannot read it", ".msh (2.2 or 4.1)")
    _refused(tmp_path / "absent.msh", "cannot read the mesh file")


def test_a_mesh_built_in_code_is_checked_as_a_file_is():
    with pytest.raises(MeshError, match="degenerate"):
        PlaneMesh([[0, 0], [1, 0], [2, 0]], [[0, 1, 2]], "triangle")
    with pytest.raises(MeshError, match="not edges"):
        PlaneMesh(np.array(SQUARE)[:, :2], TRIS, "triangle", {"cut": [[1, 3]]})


def test_a_vtu_mesh_is_read_without_groups(tmp_path):
    """meshio's other formats carry the cells (no Gmsh groups): the same body,
    the same matrices; a support then names no group the file has.  (XDMF
    goes the same way through meshio, whose writer needs h5py, so it is not
    written here.)"""
    import meshio
    m = rectangle(1.0, 0.1, 6, 2)
    pts = np.c_[m.points, np.zeros(len(m.points))]
    for suffix in (".vtu",):
        path = tmp_path / f"strip{suffix}"
        meshio.write(path, meshio.Mesh(pts, [("triangle", m.cells)]))
        mesh = read_mesh(path)
        assert mesh.groups == {} and np.array_equal(mesh.points, m.points)
        a = Plane(path, **STEEL).assemble()
        b = Plane(m, **STEEL).assemble()
        assert (a.stiffness != b.stiffness).nnz == 0 and (a.mass != b.mass).nnz == 0
        with pytest.raises(MeshError, match=r"no boundary group 'left' \(its groups: none\)"):
            Plane(path, fixed="left", **STEEL).assemble()
