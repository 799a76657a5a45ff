"""The table of scene keys (cosim.scene.keys) and the loader agree.

Every key the loader accepts is in the table (the loader's table reader
refuses to read a key the table lacks, and refuses a key of the file the
table lacks), and every key in the table is accepted: the shipped scenes and
their variants, plus the constructed scenes below, walk every row of every
fixed section.  The reference the documentation includes is rendered from
the same table.
"""
from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
import tomllib
import warnings
from pathlib import Path

import pytest

from cosim.scene import keys
from cosim.scene.checks import SceneError, Table, record_keys
from cosim.scene.load import load_scene

CASES = Path(__file__).resolve().parents[1] / "cases"
SPRING_DROP = CASES / "spring_drop.toml"
M = "subsystems.body.bodies.mass"
C = "contacts.wall"

_STRUCTURE_TAIL = ('direction=[0.0, 1.0], rayleigh=[0.0, 0.0], points={p=0.5}, '
                   'modes={count=2, cutoff_hz=1e4}, initial_velocity=0.0, '
                   'static_equilibrium=true, static_loads={p=1.0}')
_LINE = 'length=1.0, density=1000.0, elements=4, origin=[0.0, 0.0], axis=[1.0, 0.0]'

#: (scene, variant, overrides) that reach the rows no shipped scene holds
CONSTRUCTED = [
    (SPRING_DROP, None, [
        "output.every=1", "output.export_every=1", "output.export=[]", "output.estimate=true",
        "guard.energy_growth=0.1", "guard.energy_check=true", "guard.energy_floor=0.001",
        "guard.energy_warning=0.01", "guard.coupling_warning=0.01",
        "guard.chatter_switches=100", "guard.chatter_window=1e-6", "guard.max_steps=1e9",
        f"{M}.joint.angle=0.0", f"{M}.joint.spring={{stiffness=0.0, rest=0.0}}",
        f"{M}.joint.damper={{damping=0.0}}",
        f'{M}.joint.drive={{type="constant", torque=0.0}}',
        f"{C}.friction={{coefficient=0.5, slip_velocity=0.01}}",
        f'subsystems.s={{type="string", {_LINE}, tension=1.0, area=1e-4, {_STRUCTURE_TAIL}, '
        f'integrator={{method="hht_alpha", alpha=-0.05}}}}',
        f'subsystems.r={{type="rod", {_LINE}, youngs_modulus=1e9, area=1e-4, left="fixed", '
        f'right="free", rayleigh=[0.0, 0.0], points={{p=0.5}}, modes={{count=2}}, '
        f'static_equilibrium=true, static_loads={{p=1.0}}, '
        f'integrator={{method="generalized_alpha", rho_inf=0.8}}}}',
        f'subsystems.bm={{type="beam", {_LINE}, youngs_modulus=1e9, section={{diameter=0.01}}, '
        f'left="pinned", right="pinned", tension=0.0, {_STRUCTURE_TAIL}, '
        f'integrator={{method="newmark", contact_step=1e-6, beta=0.25, gamma=0.5}}}}',
        f'subsystems.cb={{type="cable", {_LINE}, youngs_modulus=1e9, '
        f'section={{width=0.01, height=0.01}}, left="pinned", right="pinned", tension=10.0, '
        f'{_STRUCTURE_TAIL}, integrator={{method="exact"}}}}',
        'subsystems.ch={type="chain", masses=[1.0, 1.0], stiffnesses=[1.0, 1.0], '
        'ground_below=true, spacing=0.1, origin=[0.0, 0.0], direction=[0.0, 1.0], '
        'rayleigh=[0.0, 0.0], points={p=1}, modes={count=1}, integrator={method="exact"}, '
        'initial_velocity=0.0, static_equilibrium=true, static_loads={p=1.0}}',
    ]),
    (SPRING_DROP, None, [
        'subsystems.pl={type="plane", mesh="../tests/data/plate.msh", scale=1e-3, '
        'model="plane_stress", thickness=0.01, youngs_modulus=2e11, poisson_ratio=0.3, '
        'density=7850.0, element="P2", supports={fixed="clamp", fixed_x=["tip"], '
        'fixed_y="tip"}, origin=[0.0, 0.0], angle=0.0, rayleigh=[0.0, 0.0], '
        'points={p={boundary="face", s=0.1}}, modes={count=2, cutoff_hz=1e4, '
        'static_correction=false, cache=".plane-modes"}, integrator={method="exact"}, static_equilibrium=true, '
        'static_loads={p=1.0}, initial_velocity=[0.0, 0.0]}',
        # a circle against the plane body (built and run in tests/test_plane_circle_scene.py)
        'contacts.circle={a="body.tip", b="pl.p", normal=[0.0, 1.0], radius=0.01, '
        'placement="embedded", law={type="linear", contact_stiffness=1e12}}']),
    (SPRING_DROP, None, [
        f'{M}.joint.drive={{type="table", times=[0.0, 1.0], torques=[0.0, 0.0]}}']),
    (SPRING_DROP, None, [
        f'{M}.joint.drive={{type="pd", kp=0.0, kd=0.0, max_torque=10.0, reference='
        f'{{type="table", times=[0.0, 1.0], values=[0.0, 0.0]}}}}']),
    (SPRING_DROP, None, [
        f'{M}.joint.drive={{type="pd", kp=0.0, kd=0.0, reference={{type="sinusoid", '
        f'amplitude=0.0, frequency=1.0, phase=0.0, offset=0.0}}}}']),
    (SPRING_DROP, None, [
        f"{C}.grasp={{stiffness=1e6, damping=0.0, tangential_stiffness=0.0, "
        f"tangential_damping=0.0, close={{time=0.001}}, release={{time=0.002}}}}"]),
    (SPRING_DROP, None, [
        'subsystems.arm={type="multibody", bodies={link={mass=1.0, points={hand=[0.0, 0.0]}, '
        'joint={name="y", type="prismatic", axis=[1.0, 0.0]}}}}',
        f'{C}.b="arm.hand"', f'{C}.placement="embedded"', f'{C}.host="body"']),
]


def _scenarios():
    for path in sorted(CASES.glob("*.toml")):
        data = tomllib.loads(path.read_text())
        for variant in [None, *data.get("variants", {})]:
            yield path, variant, []
    yield from CONSTRUCTED


def _walk():
    """{scenario index: set of (section id, key name, key path)} accepted."""
    out = {}
    for i, (path, variant, overrides) in enumerate(_scenarios()):
        with warnings.catch_warnings(), record_keys() as found:
            warnings.simplefilter("ignore")
            load_scene(path, variant, overrides)
        out[i] = set(found)
    return out


WALK = None


def walk():
    global WALK
    if WALK is None:
        WALK = _walk()
    return WALK


def _canonical(section_id):
    """A section listed under two ids (beam and cable) counts once."""
    if section_id is None or section_id.startswith("law."):
        return section_id
    sec = keys.SECTIONS[section_id]
    return next(sid for sid, s in keys.SECTIONS.items() if s is sec)


#: rows the reader takes out before the table reader sees the scene
#: (variants are merged by cosim.scene.read), and the generic subsystem
#: section, whose only key `type` every kind's section repeats
_NOT_WALKED = {("top", "variants"), ("top", "default_variant"), ("variants", "NAME"),
               ("subsystem", "type")}
#: the FMU sections: their scene needs an FMU compiled at test time, so
#: tests/test_fmu.py walks them (test_every_fmu_key_of_the_table_is_accepted)
FMU_SECTIONS = {sid for sid in keys.SECTIONS if sid == "fmu" or sid.startswith("fmu.")}
_NOT_WALKED |= {(sid, k.name) for sid in FMU_SECTIONS for k in keys.SECTIONS[sid].keys}


def test_every_key_of_the_table_is_accepted_by_the_loader():
    covered = {(_canonical(s), name) for found in walk().values() for s, name, _ in found}
    rows = {(_canonical(sid), k.name) for sid, sec in keys.SECTIONS.items() for k in sec.keys}
    missing = sorted(rows - covered - _NOT_WALKED)
    assert not missing, f"rows of the table no scene reaches: {missing}"


def test_every_key_the_loader_accepts_is_in_the_table():
    """What a table with a section accepted is a row of that section (the
    scheme's keys come from the scheme registry and carry no section)."""
    for found in walk().values():
        for sid, name, path in found:
            if sid is None:
                assert path.startswith("scheme"), path
                continue
            assert keys.section(sid).find(path.rpartition(".")[2]) is not None, path
            assert name in [k.name for k in keys.section(sid).keys], (sid, name)


def test_variants_and_default_variant_are_read():
    s = load_scene(SPRING_DROP)
    assert s.variant == "undamped"          # default_variant, and variants.NAME


def _one_table_per_section():
    """(section id, table path, scenario) for one table of each section."""
    seen = {}
    scen = list(_scenarios())
    for i, found in walk().items():
        for sid, name, path in sorted(found, key=lambda f: (str(f[0]), f[2])):
            if sid is None or _canonical(sid) in seen:
                continue
            sec = keys.section(sid)
            if all(k.placeholder for k in sec.keys):
                continue              # any name is a key there (points, loads, ...)
            seen[_canonical(sid)] = (path.rpartition(".")[0], scen[i])
    return seen


def test_a_key_outside_the_table_is_refused_in_every_section():
    tables = _one_table_per_section()
    assert {"top", "output", "guard", "effects", "multibody", "joint", "body", "contact",
            "grasp", "trigger", "friction", "beam", "chain", "rod", "string", "section",
            "modes", "structure.integrator", "multibody.integrator",
            "law.linear"} <= set(tables)
    for sid, (table, (path, variant, overrides)) in sorted(tables.items()):
        key = f"{table}.not_a_key" if table else "not_a_key"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with pytest.raises(SceneError, match=re.escape(f"`{key}` is not a known key of")):
                load_scene(path, variant, overrides + [f"{key}=1"])


def test_required_and_default_come_from_the_table():
    """A required row is required, a default row is the value the scene gets."""
    with pytest.raises(SceneError, match=re.escape(f"`{M}.mass` is required but missing")):
        load_scene(SPRING_DROP, overrides=[f'{M}={{points={{tip=[0.0, 0.0]}}, joint='
                                           f'{{name="x", type="prismatic"}}}}'])
    s = load_scene(SPRING_DROP)
    body = s.subsystems[0].bodies[0]
    assert body.inertia == keys.SECTIONS["body"].find("inertia").default
    assert s.output_every == keys.SECTIONS["output"].find("every").default
    assert s.guard.energy_floor == keys.SECTIONS["guard"].find("energy_floor").default
    assert s.contacts[0].offset == keys.SECTIONS["contact"].find("offset").default


def test_the_loader_cannot_read_a_key_the_table_lacks():
    t = Table({"mass": 1.0}, ("b",), "f.toml", "body")
    with pytest.raises(RuntimeError, match="does not list"):
        t.number("weight")
    with pytest.raises(RuntimeError, match="the table of keys'"):
        t.number("inertia", 0.0)          # its default is the table's


@pytest.mark.parametrize("law", list(__import__("couplers").CONTACT_LAWS))
def test_a_law_section_is_its_dataclass(law):
    from couplers import CONTACT_LAWS
    sec = keys.law_section(law)
    fields = dataclasses.fields(CONTACT_LAWS[law])
    assert [k.name for k in sec.keys] == ["type"] + [f.name for f in fields]
    for f in fields:
        row = sec.find(f.name)
        assert row.default == (keys.REQUIRED if f.default is dataclasses.MISSING else f.default)
        assert row.meaning


def test_the_scheme_section_holds_every_option_of_every_scheme():
    from cosim.core.schemes import COUPLING_SCHEMES
    sec = keys.scheme_section()
    for name in COUPLING_SCHEMES:
        for opt in COUPLING_SCHEMES[name].options:
            row = sec.find(opt)
            assert row.name == opt and name in row.check and row.meaning, (name, opt)


def test_reference_markdown_has_a_table_per_section():
    text = keys.reference_markdown()
    assert text.endswith("\n") and not text.endswith("\n\n")
    assert all(line == line.rstrip() for line in text.splitlines())
    headings = [line for line in text.splitlines() if line.startswith("## ")]
    assert "## [scheme]" in headings and "## top level" in headings
    assert '## [contacts.NAME.law] with type = "hertz"' in headings
    assert len(headings) == len(set(headings))
    for block in text.split("\n## ")[1:]:
        lines = block.splitlines()
        assert lines[2] == "| key | unit | default | check | meaning |", lines[0]
        assert all(row.count(" | ") >= 4 for row in lines[4:] if row), lines[0]
    row = next(line for line in text.splitlines() if line.startswith("| `t_end` | s |"))
    assert row == "| `t_end` | s | required | > 0 | end time of the run |"
    assert "| `contact_step` | s | `1e-06` | > 0 |" in text


def test_reference_markdown_builds_with_sphinx_without_warnings(tmp_path):
    pytest.importorskip("myst_parser")
    (tmp_path / "conf.py").write_text('extensions = ["myst_parser"]\n'
                                      'master_doc = "index"\n')
    (tmp_path / "index.md").write_text("# Scene keys\n\n" + keys.reference_markdown())
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "-q", "-b", "html",
                           str(tmp_path), str(tmp_path / "_build")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    html = (tmp_path / "_build" / "index.html").read_text()
    assert html.count("<table") == len(keys._ordered_sections())
