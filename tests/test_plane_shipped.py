"""The shipped scenes of plane bodies: they run by name, the committed mesh
of beam_with_holes is what its Gmsh script describes, and docs/structures.md's
numbers of it are the run's."""
import json
import re
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES
from documented import Claim, assert_printed, assert_reproduced
from cosim import cli

GEO = CASES / "beam_with_holes.geo"
MSH = CASES / "beam_with_holes.msh"
PAGE = "docs/structures.md"
#: C's first contact on the beam with holes ends at 0.1055 s, its second at 0.1089 s
SHORT = 0.11


def _geo_numbers() -> dict:
    """The parameters the script sets at its top (``NAME = NUMBER;``)."""
    return {k: float(v) for k, v in re.findall(r"^(\w+) = ([-+.\deE]+);", GEO.read_text(),
                                               flags=re.M)}


def _geo_groups() -> dict:
    """Physical group name -> dimension, as the script names them."""
    dims = {"Point": 0, "Curve": 1, "Surface": 2}
    return {name: dims[kind] for kind, name in
            re.findall(r'^Physical (Point|Curve|Surface)\("(\w+)"\)', GEO.read_text(), re.M)}


@pytest.mark.parametrize("name", ["beam_impact_2d", "beam_with_holes"])
def test_the_shipped_plane_scenes_run_by_name(name, tmp_path, monkeypatch, capsys):
    """`cosim run NAME` from a folder that is not the repository finds the
    scene and its mesh beside it; C strikes the body."""
    monkeypatch.chdir(tmp_path)
    code = cli.main(["run", name, "--set", f"t_end={SHORT}", "--no-estimate", "--quiet",
                     "--out", "run"])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["scene"] == name and summary["status"] == "finished"
    assert summary["contacts"]["C"]["count"] >= 1


def test_the_committed_mesh_is_what_the_script_describes():
    """The .msh holds the script's physical groups and nothing else, the
    beam's outline (L x H, the pin at mid-height of the left end) and its N
    holes of radius R: every hole vertex on its circle, each hole a loop of
    about 2 pi R / lh segments, and the area the rectangle's less the
    holes' polygons."""
    import meshio
    from fem.plane import dof_count, outline, read_mesh

    g = _geo_numbers()
    L, H, R, N, lh = g["L"], g["H"], g["R"], int(g["N"]), g["lh"]
    raw = meshio.read(MSH)
    assert {k: int(v[1]) for k, v in raw.field_data.items()} == _geo_groups()
    mesh = read_mesh(MSH)
    p = mesh.points
    tol = 1e-12 * L
    assert np.allclose(p.min(axis=0), [0.0, -H], atol=tol)
    assert np.allclose(p.max(axis=0), [L, 0.0], atol=tol)
    for group, axis, value in (("top", 1, 0.0), ("bottom", 1, -H), ("left", 0, 0.0),
                               ("right", 0, L)):
        assert np.all(np.abs(p[mesh.vertices(group), axis] - value) <= tol), group
    assert np.allclose(p[mesh.point_groups["pin"]], [[0.0, -H / 2]], atol=tol)
    centres = np.column_stack([L * np.arange(1, N + 1) / (N + 1), np.full(N, -H / 2)])
    hole = p[mesh.vertices("holes")]
    dist = np.hypot(*(hole[:, None, :] - centres[None]).transpose(2, 0, 1)).min(axis=1)
    assert np.all(np.abs(dist - R) <= 1e-9 * R)
    loops = outline(mesh.cells)
    assert len(loops) == N + 1                              # the outer edge and N holes

    def area(loop):
        x, y = p[loop].T
        return 0.5 * float(np.sum(x[:-1] * y[1:] - x[1:] * y[:-1]))

    areas = sorted((area(lp) for lp in loops), key=abs)
    outer, holes = areas[-1], areas[:-1]
    assert outer == pytest.approx(L * H, rel=1e-12)        # counter-clockwise
    for a in holes:                                          # clockwise, an inscribed polygon
        assert -np.pi * R * R < a < -0.97 * np.pi * R * R
    counts = [lp.size - 1 for lp in loops if abs(area(lp)) < L * H / 2]
    assert all(0.7 * 2 * np.pi * R / lh <= c <= 1.3 * 2 * np.pi * R / lh for c in counts)
    e1 = p[mesh.cells[:, 1]] - p[mesh.cells[:, 0]]
    e2 = p[mesh.cells[:, 2]] - p[mesh.cells[:, 0]]
    cell_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert cell_area == pytest.approx(outer + sum(holes), rel=1e-12)
    # the numbers docs/structures.md gives of it
    assert_printed(Claim(PAGE, "P2 on 2114 triangles", "read_mesh", 2114))
    assert mesh.cells.shape[0] == 2114
    assert dof_count(mesh, "P2") == 9204                    # 9177 free: the supports hold 27


def test_gmsh_makes_the_committed_mesh_from_the_script(tmp_path):
    """With the `mesh` extra's gmsh of the version that made it, the script
    gives a mesh of the same vertices, cells and groups."""
    gmsh = pytest.importorskip("gmsh")
    if gmsh.__version__ != "4.15.2":
        pytest.skip(f"the mesh was made by gmsh 4.15.2, this is {gmsh.__version__}")
    from fem.plane import read_mesh

    out = tmp_path / "again.msh"
    gmsh.initialize(["gmsh", "-v", "0"])
    try:
        gmsh.open(str(GEO))
        gmsh.model.mesh.generate(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(out))
    finally:
        gmsh.finalize()
    a, b = read_mesh(MSH), read_mesh(out)
    assert a.points.shape == b.points.shape and a.cells.shape == b.cells.shape
    assert np.max(np.abs(a.points - b.points)) <= 1e-12
    assert {k: v.shape for k, v in a.groups.items()} == {k: v.shape for k, v in b.groups.items()}


def test_the_beam_with_holes_example_numbers_are_the_runs():
    scene = cosim.load_scene(CASES / "beam_with_holes.toml", overrides=[f"t_end={SHORT}"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        system, _ = scene.build()
        res = cosim.simulate(scene, estimate=False)
    beam = system.subsystems[[s.name for s in system.subsystems].index("beam")]
    law = system.links[system.contact_names.index("C")].contact.law
    c = res.summary["contacts"]["C"]
    on, off = c["intervals"][0]
    f = beam.natural_frequencies_hz
    cmd = "cosim run beam_with_holes (tests/test_plane_shipped.py)"
    for printed, value, measured, tol in (
            ("9177 free DOFs", 9177, beam.structure.n_dof, 0),
            ("the modes below 20 kHz are 24", 24, beam.n_modes, 0),
            ("143.7 Hz", 143.7, f[0], 0.05),
            ("to 13.9 kHz", 13.9, f[-1] / 1e3, 0.05),
            ("1.5972e6 N/m", 1.5972e6, law.contact_stiffness, 50.0),
            ("C strikes twice", 2, c["count"], 0),
            ("lasts 2.768 ms", 2.768, 1e3 * (off - on), 5e-4),
            # the peak penetration is the first contact's (the second is lighter)
            ("peak force of 7.14 kN", 7.14, law.contact_stiffness * c["peak_penetration"] / 1e3,
             5e-3)):
        claim = Claim(PAGE, printed, cmd, value, abs=tol)
        assert_printed(claim)
        assert_reproduced(claim, measured)
    assert f[-1] < 20e3 and beam.natural_frequencies_hz.size == 24
    first = (res.t >= on) & (res.t <= off)
    assert np.abs(res.series["force/C"][first]).max() == pytest.approx(
        law.contact_stiffness * c["peak_penetration"], rel=2e-3)   # sampled every 50 us
