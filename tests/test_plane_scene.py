"""A plane body in a scene (``type = "plane"``): read and checked like every
structure, its points on the boundary, struck through a point contact along
the boundary's normal; the 2-D twin of beam_impact against the 1-D run; the
compiled kernels against the numpy reference; its records are modes."""
import json
import math
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

import cosim
from conftest import CASES
from documented import Claim, assert_printed, assert_reproduced
from plane_files import write_msh
from cosim import cli
from cosim.scene.load import SceneError
from cosim.sides.fem import StructureSubsystem

DATA = Path(__file__).parent / "data"
TWIN = CASES / "beam_impact_2d.toml"
#: C's two contacts end at 0.1217 s; the runs stop just past the last release
SHORT = ["t_end=0.125"]

STRIKE = """\
name = "plate_strike"
t_end = 1e-3

[scheme]
name = "gauss_seidel"
macro_step = 1e-5

[subsystems.plate]
type = "plane"
mesh = "plate.msh"
scale = 1e-3
thickness = 0.01
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7850.0
supports = {{ fixed = "clamp" }}
points = {{ hit = {{ boundary = "face", s = 0.02 }} }}
modes = {{ count = 20{modes} }}
integrator = {{ contact_step = 1e-7 }}

[subsystems.striker]
type = "multibody"
integrator = {{ method = "rk4", max_step = 1e-6 }}

[subsystems.striker.bodies.ball]
mass = 0.2
inertia = 1e-5
points = {{ tip = [0.0, 0.0] }}
joint = {{ name = "y", type = "prismatic", parent = "ground", axis = [0.0, 1.0], offset = [0.18, 0.05], dq0 = -1.0 }}

[contacts.hit]
a = "striker.tip"
b = "plate.hit"
normal = [0.0, 1.0]
law = {law}
placement = "embedded"
"""
LINEAR = '{ type = "linear", contact_stiffness = 1e7 }'


def _strike(tmp_path, modes="", law=LINEAR, **replace) -> Path:
    shutil.copy(DATA / "plate.msh", tmp_path / "plate.msh")
    text = STRIKE.format(modes=modes, law=law)
    for old, new in replace.items():
        assert old.replace("_", " ") in text or old in text
        text = text.replace(old, new)
    path = tmp_path / "strike.toml"
    path.write_text(text)
    return path


def _refused(path, key, *words):
    with pytest.raises(SceneError) as info:
        cosim.load_scene(path).build()
    msg = str(info.value)
    assert str(path) in msg and key in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


# ---------------------------------------------------------------------------
# The 2-D twin of beam_impact
# ---------------------------------------------------------------------------
def test_the_twin_of_beam_impact_has_the_beams_frequency_and_first_impact():
    """beam_impact's beam meshed in the plane (P2, 100 x 2 x 2 triangles,
    plane stress, pinned at its end faces) against the 1-D Euler-Bernoulli
    beam of the scene, both struck at 0.45 m by the same robot with C's
    point held in place (``follow = false``; a plane body's port stays put):
    f1 within 0.1 % (measured -0.015 %: shear and rotary inertia at
    L/H = 100), the first contact's peak force and duration within 1 %
    (measured -0.08 % and +0.11 %) with the static correction of the
    dropped modes in series with C's spring."""
    runs = {}
    for name, path, over in (("1d", CASES / "beam_impact.toml", ["contacts.C.follow=false"]),
                             ("2d", TWIN, [])):
        scene = cosim.load_scene(path, overrides=SHORT + over)
        system, _ = scene.build()
        beam = system.subsystems[[s.name for s in system.subsystems].index("beam")]
        law = system.links[system.contact_names.index("C")].contact.law
        res = cosim.simulate(scene)
        c = res.summary["contacts"]["C"]
        on, off = c["intervals"][0]
        runs[name] = dict(f1=beam.natural_frequencies_hz[0], k=law.contact_stiffness,
                          peak=law.contact_stiffness * c["peak_penetration"],
                          duration=off - on, count=c["count"], res=res)
    a, b = runs["1d"], runs["2d"]
    assert abs(b["f1"] / a["f1"] - 1) < 1e-3
    cmd = "tests/test_plane_scene.py, the twin of beam_impact"
    for printed, value, measured in (
            ("f1 23.4497 Hz", 23.4497, b["f1"]), ("the 1-D beam's 23.4533", 23.4533, a["f1"]),
            ("within 0.08 % in peak force", 0.08, 100 * abs(b["peak"] / a["peak"] - 1)),
            ("0.11 % in duration", 0.11, 100 * abs(b["duration"] / a["duration"] - 1))):
        claim = Claim("docs/structures.md", printed, cmd, value, abs=0.5 * 10 ** -(
            len(f"{value}".split(".")[1])))
        assert_printed(claim)
        assert_reproduced(claim, measured)
    assert b["k"] < a["k"] == 1.6e6                  # the correction softened C's spring
    assert b["count"] == a["count"] == 2
    # the peak penetration is the first contact's (the second is lighter)
    assert abs(b["peak"] / a["peak"] - 1) < 1e-2
    assert abs(b["duration"] / a["duration"] - 1) < 1e-2
    # the plane body records its modal coordinates, not its 2000 DOFs
    names = [k for k in b["res"].series if k.startswith("q/beam/")]
    assert names[0] == "q/beam/mode1" and len(names) == b["res"].summary["final_state"] \
        .get("beam", {}).__len__() < 100


def test_compiled_and_numpy_kernels_agree_on_the_twin(monkeypatch):
    """The compiled structure step takes the plane body by its ports' modal
    rows along their normal, as it takes a beam: it steps the twin (a
    kernel is built) and agrees with the numpy reference to round-off
    (measured: contact times 4e-16 s apart, series within 5e-12 of their
    largest values; bound 1e-10 as tests/test_kernel.py's)."""
    built, out = [], {}
    original = StructureSubsystem._build_kernel

    def spy(self):
        k = original(self)
        built.append((kernel, k))
        return k

    monkeypatch.setattr(StructureSubsystem, "_build_kernel", spy)
    for kernel in ("numpy", "compiled"):
        monkeypatch.setenv("COSIM_KERNEL", kernel)
        # past C's first contact (0.1028 s to 0.1052 s)
        out[kernel] = cosim.simulate(cosim.load_scene(TWIN, overrides=["t_end=0.107"]))
    assert any(k is not None for kern, k in built if kern == "compiled")
    assert all(k is None for kern, k in built if kern == "numpy")
    ref, fast = out["numpy"], out["compiled"]
    for name, c in ref.summary["contacts"].items():
        np.testing.assert_allclose(np.ravel(fast.summary["contacts"][name]["intervals"]),
                                   np.ravel(c["intervals"]), rtol=0, atol=1e-9, err_msg=name)
    assert set(fast.series) == set(ref.series)
    for key in ref.series:
        a, b = np.asarray(ref.series[key]), np.asarray(fast.series[key])
        scale = max(float(np.max(np.abs(a))), 1e-300)
        assert np.max(np.abs(a - b)) <= 1e-10 * scale, key


# ---------------------------------------------------------------------------
# A striker on a plate read from a Gmsh file
# ---------------------------------------------------------------------------
def test_cosim_info_gives_the_dofs_and_frequencies(tmp_path, capsys):
    path = _strike(tmp_path)
    assert cli.main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    plate = info["subsystems"]["plate"]
    assert plate["dofs"] == 2 * (27 + 58) - 2 * 5           # P2 on the plate, clamp held
    assert plate["modes_kept"] == 20
    f = np.array(plate["natural_frequencies_hz"])
    assert f[0] == pytest.approx(1003, rel=2e-3) and np.all(np.diff(f) > 0)
    assert "frequency_hz" in json.dumps(info["contacts"]["hit"])
    # the mode rule: the spring on the striker's 0.2 kg, against the top kept mode
    (rule,) = plate["mode_rule"]
    assert rule["contact"] == "hit" and rule["static_correction"] is False
    assert rule["frequency_hz"] == pytest.approx(math.sqrt(1e7 / 0.2) / (2 * math.pi),
                                                 rel=1e-12)
    assert rule["kept_to_hz"] == f[-1] and rule["ratio"] == rule["kept_to_hz"] / \
        rule["frequency_hz"]
    assert rule["verdict"] == ("ok" if rule["ratio"] >= 10 else "warn")
    assert cli.main(["info", str(path)]) == 0
    assert f"{rule['ratio']:.3g} x contact hit's 1125 Hz" in capsys.readouterr().out


def test_the_strike_runs_and_closes_its_energy(tmp_path):
    res = cosim.simulate(cosim.load_scene(_strike(tmp_path)))
    assert res.status == "finished"
    c = res.summary["contacts"]["hit"]
    assert c["count"] >= 1 and c["peak_penetration"] > 0
    e = res.summary["energy"]
    assert abs(e["final"] - e["initial"]) < 1e-3 * e["initial"]


def test_the_static_correction_softens_the_spring_by_the_dropped_compliance(tmp_path):
    from fem.plane.reduce import StaticCorrection
    scene = cosim.load_scene(_strike(tmp_path, modes=", static_correction = true"))
    system, _ = scene.build()
    plate = system.subsystems[0]
    k = system.links[0].contact.law.contact_stiffness
    c_r = StaticCorrection(plate.structure, plate.basis).compliance(("face", 0.02))
    assert c_r > 0 and k == pytest.approx(1e7 / (1 + 1e7 * c_r), rel=1e-14)


def test_a_second_build_reads_the_modes_from_the_cache(tmp_path, monkeypatch):
    from fem.plane import cache
    path = _strike(tmp_path, modes=', cache = "modes-cache"')
    first, _ = cosim.load_scene(path).build()
    entries = list((tmp_path / "modes-cache").iterdir())
    assert len(entries) == 1 and entries[0].suffix == ".npz"
    monkeypatch.setattr(cache, "modes", lambda *a, **k: pytest.fail("solved again"))
    again, _ = cosim.load_scene(path).build()
    assert np.array_equal(again.subsystems[0].omega, first.subsystems[0].omega)
    (tmp_path / "taken").write_text("")
    path = _strike(tmp_path, modes=', cache = "taken"')
    _refused(path, "subsystems.plate.modes.cache", "not a folder")


# ---------------------------------------------------------------------------
# Refusals and warnings
# ---------------------------------------------------------------------------
def test_a_mesh_trap_is_refused_at_the_mesh_key(tmp_path):
    path = _strike(tmp_path, **{'mesh = "plate.msh"': 'mesh = "absent.msh"'})
    _refused(path, "subsystems.plate.mesh", "absent.msh", "cannot read the mesh file")
    path = _strike(tmp_path, **{"scale = 1e-3": "scale = 1e-3\nelement = \"Q2\""})
    _refused(path, "subsystems.plate.mesh", "needs quad cells", "P1 or P2")


def test_groups_and_points_are_checked_against_the_mesh(tmp_path):
    path = _strike(tmp_path, **{'fixed = "clamp"': 'fixed = "wall"'})
    _refused(path, "subsystems.plate.supports.fixed", "no boundary group 'wall'",
             "'clamp', 'face', 'tip'")
    path = _strike(tmp_path, **{'boundary = "face"': 'boundary = "side"'})
    _refused(path, "subsystems.plate.points.hit.boundary", "no boundary group 'side'")
    path = _strike(tmp_path, **{"s = 0.02": "s = 0.3"})
    _refused(path, "subsystems.plate.points.hit.s", "[0, 0.2] m along `face`")


@pytest.mark.filterwarnings("ignore:.*is a point contact on the plane body")
def test_the_correction_needs_a_linear_law_and_modes_above_the_contact(tmp_path):
    hertz = '{ type = "hertz", contact_stiffness = 1e9, exponent = 1.5 }'
    path = _strike(tmp_path, modes=", static_correction = true", law=hertz)
    _refused(path, "modes.static_correction", "`hertz` law", "use `linear`")
    # 2 modes (1.0 and 5.1 kHz) against a 1e9 N/m spring on 0.2 kg (11 kHz)
    path = _strike(tmp_path, modes=", static_correction = true",
                   law='{ type = "linear", contact_stiffness = 1e9 }',
                   **{"count = 20": "count = 2"})
    _refused(path, "modes.static_correction", "x the contact frequency", "turn the correction off")


def test_a_stiff_point_contact_is_warned_as_mesh_dependent_once(tmp_path):
    path = _strike(tmp_path, law='{ type = "linear", contact_stiffness = 1e9 }')
    with pytest.warns(UserWarning, match=r"grows by 0\.21 of the spring's .* spread the "
                                         r"contact"):
        cosim.load_scene(path).build()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cosim.load_scene(path).build()                       # said once in a process
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cosim.load_scene(_strike(tmp_path)).build()          # 1e7 N/m: 2e-3, quiet


def test_the_mesh_is_an_input_of_the_scene(tmp_path):
    from cosim.scene.inputs import input_digests
    scene = cosim.load_scene(_strike(tmp_path))
    digests = input_digests(scene)
    assert set(digests) == {"scene", "subsystems.plate.mesh"}
    assert math.isfinite(len(digests["subsystems.plate.mesh"]))


# ---------------------------------------------------------------------------
# The twin of rod_impact: a wall on the whole end face
# ---------------------------------------------------------------------------
def test_the_twin_of_rod_impact_is_rod_impact(tmp_path):
    """rod_impact's rod as a Q1 strip (160 x 1 cells, nu = 0, free), moving
    at 1 m/s onto the wall through a port on its whole end face: the face's
    mean normal displacement, with consistent weights (a force on it is a
    uniform traction).  With nu = 0 the strip's axial motion is the P1 rod's
    on the same nodes and the face's mean sees no other mode, so the run is
    rod_impact's: contact intervals to 1e-12 s, impulse and peak to 1e-9
    (measured: 1.5e-16 s, 2.2e-12 and 3.9e-12)."""
    from fem.plane import rectangle
    write_msh(tmp_path / "rod_2d.msh", rectangle(1.0, 0.01, 160, 1, "quad"), "rod")
    src = (CASES / "rod_impact.toml").read_text()
    body = """[subsystems.rod]
type = "plane"
mesh = "rod_2d.msh"
thickness = 0.01              # x 10 mm in the plane: the rod's 1e-4 m^2
youngs_modulus = 210e9
poisson_ratio = 0.0
density = 7850.0
element = "Q1"
initial_velocity = [-1.0, 0.0]
points = { end = { boundary = "left" } }
integrator = { method = "exact", contact_step = 6e-8 }

"""
    i, j = src.index("[subsystems.rod]"), src.index("[subsystems.wall]")
    (tmp_path / "rod_2d.toml").write_text(src[:i] + body + src[j:])
    rod = cosim.simulate(cosim.load_scene(CASES / "rod_impact.toml")).summary["contacts"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")      # a face's average is no point contact (Flamant)
        twin = cosim.simulate(cosim.load_scene(tmp_path / "rod_2d.toml")).summary["contacts"]
    a, b = rod["wall"], twin["wall"]
    assert a["count"] == b["count"] == 2
    np.testing.assert_allclose(np.ravel(b["intervals"]), np.ravel(a["intervals"]), rtol=0,
                               atol=1e-12)
    assert b["impulse"] == pytest.approx(a["impulse"], rel=1e-9)
    assert b["peak_penetration"] == pytest.approx(a["peak_penetration"], rel=1e-9)


def test_a_faces_average_reads_a_translation_whole_and_a_rotation_not():
    """The mean normal displacement of the strip's right face (normal +x):
    a translation's x component whole, a small rotation about the centre
    line (u_x = -theta y, exact in P1 to Q2) nothing, and its weights sum
    to one over the face's x components."""
    from fem.plane import Plane, rectangle
    for element, kind in (("P2", "triangle"), ("Q1", "quad"), ("Q2", "quad")):
        st = Plane(rectangle(1.0, 0.1, 4, 3, kind), thickness=0.01, youngs_modulus=210e9,
                   poisson_ratio=0.3, density=7850.0, element=element).assemble()
        dofs, w = st.point_operator(("right", None))
        assert w @ st.translation((0.3, -2.0))[dofs] == pytest.approx(0.3, rel=1e-14)
        x, y = st._sbasis.doflocs                  # scalar DOF i at (x[i], y[i])
        spin = np.zeros(2 * x.size)
        spin[0::2], spin[1::2] = -1e-3 * y, 1e-3 * (x - 0.5)
        assert abs(w @ spin[st.free][dofs]) < 1e-17
        assert np.all(w[dofs % 2 == 1] == 0) and w.sum() == pytest.approx(1.0, rel=1e-14)
