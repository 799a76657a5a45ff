"""A plane body's field out of a run: the XDMF file ParaView reads (the
mesh's vertices and cells, the displacement ``Phi q`` at the recorded
times) and the animation's outline of the deformed body."""
import numpy as np
import pytest

import cosim
from test_plane_scene import _strike

#: the export keeps every 7th recorded sample
EVERY = 7


def _expected_field(sub, q):
    """Vertex displacements (T, N, 2) of modal coordinates ``q`` (T, m), from
    the kept modes and the map of free DOFs, written out here: the free DOFs
    ``Phi q`` placed in the full numbering (x, y of scalar DOF i at 2 i and
    2 i + 1; the vertices are the first scalar DOFs), zero where fixed,
    turned into the world by the body's angle."""
    st = sub.structure
    u = q @ sub.Phi.T                                      # free DOFs
    n_v = st.mesh.points.shape[0]
    full = np.zeros((q.shape[0], st.dof_map.size))
    held = st.dof_map >= 0
    full[:, held] = u[:, st.dof_map[held]]
    local = np.stack([full[:, 0:2 * n_v:2], full[:, 1:2 * n_v:2]], axis=2)
    c, s = np.cos(st.plane.angle), np.sin(st.plane.angle)
    return local @ np.array([[c, -s], [s, c]]).T


@pytest.fixture(scope="module")
def plate_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plate")
    path = _strike(tmp, **{"t_end = 1e-3": f't_end = 1e-3\n[output]\nexport = ["plate"]\n'
                                           f'export_every = {EVERY}'})
    scene = cosim.load_scene(path)
    out = tmp / "run"
    res = cosim.simulate(scene, out=out)
    assert res.success, res.message
    system, _ = scene.build()
    sub = next(s for s in system.subsystems if s.name == "plate")
    return out, res, sub


def test_the_xdmf_holds_the_bodys_mesh_and_phi_q_at_the_recorded_times(plate_run):
    meshio = pytest.importorskip("meshio")
    out, res, sub = plate_run
    st = sub.structure
    with meshio.xdmf.TimeSeriesReader(out / "plate.xdmf") as reader:
        points, cells = reader.read_points_cells()
        steps = [reader.read_data(k) for k in range(reader.num_steps)]
    # the body's mesh: its vertices in the world and its cells, as read
    assert points.shape == (st.mesh.points.shape[0], 3)
    extent = float(np.ptp(st.nodes(), axis=0).max())
    assert np.max(np.abs(points[:, :2] - st.nodes())) <= 1e-14 * extent
    assert not points[:, 2].any()
    assert [c.type for c in cells] == [st.mesh.kind]
    assert np.array_equal(cells[0].data, st.mesh.cells)
    # the recorded times, every EVERY-th, each with Phi q of its coordinates
    series = np.load(out / "series.npz")
    t = series["t"][::EVERY]
    assert len(steps) == t.size >= 10
    q = np.column_stack([series[f"q/plate/mode{i + 1}"][::EVERY] for i in range(sub.n_modes)])
    want = _expected_field(sub, q)
    scale = np.abs(want).max()
    assert scale > 1e-7                                    # the strike deformed the plate
    for k, (tk, point_data, _) in enumerate(steps):
        # times and values go through the file's decimal text: a few ulps
        assert abs(tk - t[k]) <= 4 * np.spacing(max(abs(t[k]), 1e-300))
        got = point_data["displacement"]
        assert got.shape == (points.shape[0], 3) and not got[:, 2].any()
        assert np.max(np.abs(got[:, :2] - want[k])) <= 1e-12 * scale, k
    # the clamped edge does not move
    clamp = st.mesh.vertices("clamp")
    assert not np.any(steps[-1][1]["displacement"][clamp])


def test_the_animation_draws_the_deformed_outline(plate_run):
    """The body's outline in a frame is the boundary through its vertices at
    rest plus ``magnify`` times ``Phi q`` there; the title states the factor."""
    pytest.importorskip("matplotlib")
    from cosim.plot import animation
    from cosim.plot.run_data import load_run
    from cosim.plot.scene_geometry import scene_geometry
    from fem.plane import outline

    out, res, sub = plate_run
    run = load_run(out)
    geo = scene_geometry(run.scene, out / "scene.toml")
    idx = np.array([0, len(run.t) // 2, len(run.t) - 1])
    magnify = 2000.0
    fig, draw, moving, legend = animation._figure(run, geo, idx, magnify)
    assert "deflection x2000" in fig.axes[0].get_title()
    (art,) = [a for a in moving if a.get_label() == "plate"]
    loops = outline(sub.structure.mesh.cells)
    assert len(loops) == 1                                 # the plate has no hole
    loop = loops[0]
    nodes = sub.structure.nodes()
    q = np.column_stack([run.series[f"q/plate/mode{i + 1}"][idx] for i in range(sub.n_modes)])
    want = nodes[loop][None] + magnify * _expected_field(sub, q)[:, loop]
    size = float(np.ptp(nodes, axis=0).max())
    for k in range(idx.size):
        draw(k, idx[k])
        x, y = (np.asarray(v, float) for v in art.get_data())
        assert np.isnan(x[-1]) and x.size == loop.size + 1   # the loop, then its break
        got = np.column_stack([x[:-1], y[:-1]])
        assert np.max(np.abs(got - want[k])) <= 1e-12 * size, k
    # the last frame is visibly deformed at this magnification, the first not
    moved = np.abs(want[-1] - nodes[loop]).max()
    assert moved > 1e-3 * size
    assert np.abs(want[0] - nodes[loop]).max() < 1e-3 * moved
    # at true scale the title says so
    fig1, *_ = animation._figure(run, geo, idx, 1.0)
    assert "deflection x1 (true scale" in fig1.axes[0].get_title()


def test_cosim_plot_animates_a_plane_body(plate_run, tmp_path):
    pytest.importorskip("matplotlib")
    pytest.importorskip("PIL")
    from PIL import Image

    from cosim.plot import animate_run

    out, _, _ = plate_run
    path = animate_run(out, tmp_path, max_frames=4, magnify=500.0, video="gif")
    assert path == tmp_path / "animation.gif"
    with Image.open(path) as im:
        assert im.n_frames == 4


def test_the_outline_of_a_body_with_a_hole_is_two_loops():
    from fem.plane import outline, quad_region

    # a square ring from four quadrilateral regions around a square hole
    pts, cells, offset = [], [], 0
    outer = [(0, 0), (3, 0), (3, 3), (0, 3)]
    inner = [(1, 1), (2, 1), (2, 2), (1, 2)]
    for i in range(4):
        j = (i + 1) % 4
        m = quad_region([outer[i], outer[j], inner[j], inner[i]], 3, 1)
        pts.append(m.points)
        cells.append(m.cells + offset)
        offset += m.points.shape[0]
    p = np.concatenate(pts)
    # merge the vertices the regions share
    key = np.round(p, 9)
    uniq, inverse = np.unique(key, axis=0, return_inverse=True)
    cells = inverse.ravel()[np.concatenate(cells)]
    loops = outline(cells)
    assert len(loops) == 2
    lengths = sorted(float(np.sum(np.hypot(*np.diff(uniq[lp], axis=0).T))) for lp in loops)
    assert lengths == pytest.approx([4.0, 12.0], rel=1e-12)
    for lp in loops:
        assert lp[0] == lp[-1] and np.unique(lp[:-1]).size == lp.size - 1


def test_without_the_system_the_export_builds_the_body_again(plate_run, tmp_path):
    """Called without the system that ran, the export builds the body from
    the scene: the same modes (a fixed start vector), the same field."""
    meshio = pytest.importorskip("meshio")
    from cosim.io.export import export_structures

    out, res, sub = plate_run
    scene = cosim.load_scene(out / "scene.toml")
    (path,) = export_structures(scene, res, tmp_path)
    with meshio.xdmf.TimeSeriesReader(path) as a, \
            meshio.xdmf.TimeSeriesReader(out / "plate.xdmf") as b:
        a.read_points_cells()
        b.read_points_cells()
        assert a.num_steps == b.num_steps
        last = [r.read_data(r.num_steps - 1)[1]["displacement"] for r in (a, b)]
    scale = np.abs(last[1]).max()
    assert np.max(np.abs(last[0] - last[1])) <= 1e-9 * scale


def test_the_exported_field_at_the_struck_vertex_is_what_the_contact_saw(tmp_path):
    """Struck at a vertex of the face (s = 25 mm, x = 175 mm), the exported
    displacement there is the one the contact's gap was made of: the tip at
    ``y = 0.05 + q`` against the face at ``0.05 + u_y``, so ``u_y = q - gap``
    at every recorded time (both linear in the modal coordinates: round-off)."""
    meshio = pytest.importorskip("meshio")
    path = _strike(tmp_path, **{"s = 0.02": "s = 0.025", "offset = [0.18, 0.05]":
                                "offset = [0.175, 0.05]",
                                "t_end = 1e-3": 't_end = 1e-3\n[output]\nexport = ["plate"]'})
    out = tmp_path / "run"
    res = cosim.simulate(cosim.load_scene(path), out=out, estimate=False)
    assert res.success, res.message
    with meshio.xdmf.TimeSeriesReader(out / "plate.xdmf") as reader:
        points, _ = reader.read_points_cells()
        (v,) = np.flatnonzero(np.hypot(points[:, 0] - 0.175, points[:, 1] - 0.05) < 1e-12)
        u_y = np.array([reader.read_data(k)[1]["displacement"][v, 1]
                        for k in range(reader.num_steps)])
    seen = np.asarray(res.series["q/striker/y"]) - np.asarray(res.series["gap/hit"])
    assert res.summary["contacts"]["hit"]["count"] >= 1
    assert u_y.size == seen.size and np.abs(u_y).max() > 1e-7
    assert np.max(np.abs(u_y - seen)) <= 1e-9 * np.abs(u_y).max()
