"""A misbehaving plug-in is named and blocks nothing (issue 37).

Each plug-in here is a bare distribution (its ``.dist-info`` and a module)
in a temporary folder.  A law, integrator, scheme or structure that raises,
returns the wrong thing, or exits at import makes `cosim` exit 2 with one
line naming its distribution, its entry point and what it returned (never
a traceback, never "a bug of cosim"); a name that two distributions
declare, or that is a built-in's, is refused alone, the group's other
names working; a structure's field metadata is checked when it loads.

The commands of one test run in one child process (:func:`cosim_calls`),
so that the whole file takes a few seconds of start-up.
"""
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from conftest import ROOT
from plugin_tools import bare_dist, child_env

SPRING = ROOT / "cases" / "spring_drop.toml"
STRING = ROOT / "examples" / "custom_structure" / "scene.toml"
FOUNDATION = (ROOT / "examples" / "custom_structure" / "foundation_string.py").read_text()

_CHILD = """
import contextlib, io, json, sys, traceback
from cosim import cli
out = []
for argv in json.loads(sys.argv[1]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = cli.main(argv)
        except SystemExit as exc:          # what the old code let a plug-in's sys.exit() do
            rc = exc.code
        except BaseException:
            traceback.print_exc()
            rc = "uncaught"
    out.append([rc, err.getvalue()])
print(json.dumps(out))
"""


def cosim_calls(site, calls, cwd):
    """``(exit status, stderr)`` of each `cosim` command line of ``calls``,
    run one after the other in a child process that sees ``site``."""
    proc = subprocess.run([sys.executable, "-c", _CHILD, json.dumps([list(map(str, c))
                                                                     for c in calls])],
                          capture_output=True, text=True, env=child_env(site), cwd=cwd,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return [tuple(x) for x in json.loads(proc.stdout.splitlines()[-1])]


def scene(tmp_path, base, *edits, name="scene.toml"):
    """``base`` with each ``(old, new)`` of ``edits`` made, written in ``tmp_path``."""
    text = base.read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


def blamed(result, dist, entry, group, *says):
    """``result`` is exit 2 and one error line naming the plug-in, saying ``says``."""
    rc, err = result
    assert rc == 2, err
    head = f"the plug-in distribution `{dist}` 1.0, entry point `{entry}` in group `{group}`"
    assert head in err, err
    for text in says:
        assert text in err, err
    assert "Traceback" not in err and "bug of cosim" not in err, err
    assert err.startswith("error: ") and len(err.splitlines()) == 1, err     # one line
    return err


# ------------------------------------------------------------------ laws
LAW = """
    import numpy as np
    from dataclasses import dataclass
    from typing import ClassVar
    from couplers import ContactLaw

    @dataclass(frozen=True)
    class Law(ContactLaw):
        contact_stiffness: float
        name: ClassVar[str] = "my_law"

        def force_active(self, d, dd):
            {force}

        def potential(self, d):
            return 0.5 * self.contact_stiffness * np.maximum(d, 0.0) ** 2

        def potential_slope(self, d):
            return self.contact_stiffness * np.maximum(d, 0.0)

        @property
        def stiffness(self):
            {stiffness}
    """
GOOD_FORCE = "return self.contact_stiffness * d"


@pytest.mark.parametrize("force, stiffness, says", [
    ("return (1.0, 2.0, 3.0)", "return 1e6",
     "its force_active() at d = -0.0001 m, dd = -1.0 m/s returned a tuple of 3: (1.0, 2.0, "
     "3.0), expected a finite real number (it is of shape (3,))"),
    ("return 'abc'", "return 1e6", "its force_active() at d = -0.0001 m, dd = -1.0 m/s "
                                   "returned 'abc', expected a finite real number"),
    ("raise RuntimeError('no force today')", "return 1e6",
     "its force_active() raised RuntimeError: no force today"),
    (GOOD_FORCE, "return -1.0", "its `stiffness` returned -1.0, expected a real number >= 0 "
                                "[N/m], inf for a rigid law, or NaN for none"),
    (GOOD_FORCE, "return 'stiff'", "its `stiffness` returned 'stiff', expected a real number"),
    ("return np.where(d > 0, np.nan, 0.0)", "return 1e6",
     "its force_active() at d = 1e-09 m, dd = -1.0 m/s returned nan, expected a finite real "
     "number (it is not finite)"),
], ids=["three_values", "string", "raises", "negative_stiffness", "string_stiffness", "nan"])
def test_a_law_that_returns_or_raises_wrong_is_named(tmp_path, force, stiffness, says):
    """Its outputs are judged once, as the scene builds it: `run` and `info`
    stop before anything is written."""
    site = bare_dist(tmp_path / "site", "bad-law", "cosim.laws", {"my_law": "bad_law:Law"},
                     "bad_law", LAW.format(force=force, stiffness=stiffness))
    path = scene(tmp_path, SPRING, ('type = "linear"', 'type = "my_law"'))
    results = cosim_calls(site, [["run", path, "--out", tmp_path / "run"], ["info", path]],
                          tmp_path)
    for result in results:
        blamed(result, "bad-law", "my_law = bad_law:Law", "cosim.laws", says)
    assert not (tmp_path / "run").exists()
    if force == "return (1.0, 2.0, 3.0)":        # docs/plugins.md quotes this one
        page = (ROOT / "docs" / "plugins.md").read_text(encoding="utf-8")
        assert results[0][1] in page.splitlines(keepends=True)


@pytest.mark.parametrize("fail, says", [
    ("raise ValueError('too deep')", "raised ValueError: too deep, in its force_active()"),
    ("import sys; sys.exit(0)", "raised SystemExit: 0, in its force_active()"),
], ids=["raises", "exits"])
def test_a_law_that_raises_during_the_run_is_named(tmp_path, fail, says):
    """Beyond the states it is judged on (d = 0.5 mm, inside spring_drop's
    1 mm): the run stops there, its summary says so, exit 2."""
    force = f"if np.any(d > 5e-4): {fail}\n            " + GOOD_FORCE
    site = bare_dist(tmp_path / "site", "deep-law", "cosim.laws", {"my_law": "deep_law:Law"},
                     "deep_law", LAW.format(force=force, stiffness="return 1e6"))
    path = scene(tmp_path, SPRING, ('type = "linear"', 'type = "my_law"'))
    [result] = cosim_calls(site, [["run", path, "--out", tmp_path / "run"]], tmp_path)
    err = blamed(result, "deep-law", "my_law = deep_law:Law", "cosim.laws", says)
    assert err.startswith("error: the run did not finish (failed): run stopped at t = 0.01")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert "distribution `deep-law` 1.0" in summary["message"]
    # stopped in the contact, which opens at 10 ms and lasts pi ms
    assert 0.01 < summary["t_end"] < 0.01 + np.pi * 1e-3


def test_the_law_check_accepts_every_built_in_law(monkeypatch):
    """The states a plug-in law is judged on are ones every built-in law
    answers well (a plug-in that subclasses one passes)."""
    from couplers import CONTACT_LAWS
    from cosim.core import plugin_guard
    params = {"linear": dict(contact_stiffness=1e6),
              "kelvin_voigt": dict(contact_stiffness=1e6, contact_damping=200.0),
              "rigid": dict(restitution=0.5, friction=0.2),
              "hertz": dict(contact_stiffness=1e9, exponent=1.5),
              "hunt_crossley": dict(contact_stiffness=1e9, exponent=1.5,
                                    hysteresis_damping=0.5),
              "lankarani_nikravesh": dict(contact_stiffness=1e9, exponent=1.5,
                                          restitution=0.8, impact_speed=1.0),
              "flores": dict(contact_stiffness=1e9, exponent=1.5, restitution=0.8,
                             impact_speed=1.0)}
    assert set(params) == set(CONTACT_LAWS)
    # docs/plugins.md says which states these are
    page = " ".join((ROOT / "docs" / "plugins.md").read_text(encoding="utf-8").split())
    assert "penetrations from -0.1 mm to 0.1 mm, rates of -1, 0 and 1 m/s" in page
    assert (min(plugin_guard._PENETRATIONS), max(plugin_guard._PENETRATIONS)) == (-1e-4, 1e-4)
    assert plugin_guard._RATES == (-1.0, 0.0, 1.0)
    for name, kw in params.items():
        cls = CONTACT_LAWS[name]
        monkeypatch.setitem(plugin_guard._ORIGINS, cls, f"built-in {name}")
        plugin_guard.check_law(cls(**kw))
        # and the check is real: the same law with a negative stiffness is refused
        bad = type("Bad", (cls,), {"stiffness": property(lambda self: -1.0)})
        monkeypatch.setitem(plugin_guard._ORIGINS, bad, f"bad {name}")
        with pytest.raises(ValueError, match="its `stiffness` returned -1.0"):
            plugin_guard.check_law(bad(**kw))


def test_cosim_s_own_failure_is_not_blamed_on_a_plugin(monkeypatch):
    """An exception raised in cosim's code on cosim's own objects stays
    cosim's, even with plug-ins loaded."""
    from cosim.core import plugin_guard
    from cosim.core.ode import RK4
    monkeypatch.setitem(plugin_guard._ORIGINS, type("Loaded", (), {}), "somewhere")
    with pytest.raises(ValueError) as info:
        RK4(max_step=-1.0)
    assert plugin_guard.blame(info.value) is None
    mine = type("MyRK4", (RK4,), {"name": "my_rk4"})
    monkeypatch.setitem(plugin_guard._ORIGINS, mine, "distribution `mine` 1.0")
    with pytest.raises(ValueError) as info:
        mine(max_step=-1.0)                     # cosim's check, on the plug-in's object
    assert "the plug-in distribution `mine` 1.0: made cosim's __post_init__()" in \
        str(plugin_guard.blame(info.value))


# --------------------------------------------------- integrators, schemes
STEPPER = """
    import numpy as np
    from cosim.core.ode import RK4

    class MyRK4(RK4):
        name = "my_rk4"

        def integrate(self, f, t0, y0, t1, *args, **kw):
            {body}
    """


@pytest.mark.parametrize("body, says", [
    ("return np.append(super().integrate(f, t0, y0, t1, *args, **kw), 0.0)",
     "its integrate() returned an array of shape (15,) and dtype float64, expected the state, "
     "an array of shape (14,)"),
    ("raise MemoryError('no room')", "raised MemoryError: no room, in its integrate()"),
], ids=["state_too_long", "memory_error"])
def test_an_integrator_that_returns_or_raises_wrong_is_named(tmp_path, body, says):
    site = bare_dist(tmp_path / "site", "bad-stepper", "cosim.integrators",
                     {"my_rk4": "bad_stepper:MyRK4"}, "bad_stepper", STEPPER.format(body=body))
    path = scene(tmp_path, SPRING, ('method = "rk4"', 'method = "my_rk4"'))
    [result] = cosim_calls(site, [["run", path, "--out", tmp_path / "run"]], tmp_path)
    blamed(result, "bad-stepper", "my_rk4 = bad_stepper:MyRK4", "cosim.integrators", says)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["t_end"] == 0.0


def test_a_structural_integrator_of_the_wrong_shape_is_named(tmp_path):
    """A structure's integrator whose step returns one array short."""
    code = """
        from fem.newmark import Newmark

        class Short(Newmark):
            name = "short_newmark"

            def step(self, u, v, a, h, F):
                return super().step(u, v, a, h, F)[:2]
        """
    site = bare_dist(tmp_path / "site", "short-newmark", "cosim.integrators",
                     {"short_newmark": "short_nm:Short"}, "short_nm", code)
    path = scene(tmp_path, ROOT / "cases" / "three_mass.toml")
    [result] = cosim_calls(site, [["run", path, "--variant", "f100", "--set",
                                   'subsystems.chain.integrator.method="short_newmark"',
                                   "--out", tmp_path / "run"]], tmp_path)
    blamed(result, "short-newmark", "short_newmark = short_nm:Short", "cosim.integrators",
           "its step() returned a tuple of 2", "expected three arrays (u, v, a) of shape (")


SCHEME = """
    from cosim.core.schemes import GaussSeidel

    class MyScheme(GaussSeidel):
        name = "my_scheme"

        def run(self, system, t_end, recorder):
            {body}
    """


@pytest.mark.parametrize("body, says", [
    ("raise RuntimeError('lost my way')", "raised RuntimeError: lost my way, in its run()"),
    ("return super().run(system, t_end / 2, recorder)",
     "its run() returned at t = 0.01 s, short of t_end = 0.02 s"),
], ids=["raises", "short"])
def test_a_scheme_that_raises_or_stops_short_is_named(tmp_path, body, says):
    site = bare_dist(tmp_path / "site", "bad-scheme", "cosim.schemes",
                     {"my_scheme": "bad_scheme:MyScheme"}, "bad_scheme",
                     SCHEME.format(body=body))
    path = scene(tmp_path, SPRING, ('name = "gauss_seidel"', 'name = "my_scheme"'))
    [result] = cosim_calls(site, [["run", path, "--out", tmp_path / "run"]], tmp_path)
    blamed(result, "bad-scheme", "my_scheme = bad_scheme:MyScheme", "cosim.schemes", says)
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["status"] == "failed"


def test_a_scheme_without_a_macro_step_is_refused_when_loaded(tmp_path):
    code = """
        from cosim.core.schemes.base import CouplingScheme

        class NoStep(CouplingScheme):
            name = "no_step"
            options = {}

            def run(self, system, t_end, recorder):
                return {}
        """
    site = bare_dist(tmp_path / "site", "no-step", "cosim.schemes",
                     {"no_step": "no_step:NoStep"}, "no_step", code)
    path = scene(tmp_path, SPRING, ('name = "gauss_seidel"', 'name = "no_step"'),
                 ("macro_step = 1e-4", "# no macro_step"))
    results = cosim_calls(site, [["run", path, "--out", tmp_path / "run"], ["info", path],
                                 ["sweep", path, "--set", "t_end=0.01,0.02", "--out",
                                  tmp_path / "sweep", "--no-plot", "--quiet"]], tmp_path)
    for result in results:
        blamed(result, "no-step", "no_step = no_step:NoStep", "cosim.schemes",
               "is refused: its `options` ([]) has no `macro_step`")
    assert not (tmp_path / "run").exists() and not (tmp_path / "sweep").exists()


# ------------------------------------------------------------ structures
MODEL = """
    from dataclasses import dataclass, field
    from typing import ClassVar
    import fem

    @dataclass(frozen=True)
    class Model(fem.StructureModel):
        length: float = field(metadata={length_meta})
        tension: float = 1000.0
        density: float = 7850.0
        area: float = 1e-4
        foundation_stiffness: float = 0.0
        elements: int = field(default=40, metadata={elements_meta})
        {extra}
        name: ClassVar[str] = "foundation_string"

        def dof_bound(self):
            {dof_bound}

        def assemble(self):
            {assemble}
    """
ASSEMBLE = ("return fem.String(length=self.length, tension=self.tension, density=self.density, "
            "area=self.area, n_elements=self.elements).assemble()")


def _model(length_meta="{}", elements_meta="{}", extra="", dof_bound="return self.elements + 1",
           assemble=ASSEMBLE):
    return MODEL.format(length_meta=length_meta, elements_meta=elements_meta, extra=extra,
                        dof_bound=dof_bound, assemble=assemble)


@pytest.mark.parametrize("code, says", [
    (_model(), None),                                             # the control: it runs
    (_model(length_meta='{"rule": "bogus"}'),
     "is refused: its field `length` has metadata `rule` = 'bogus', expected \">0\" or \">=0\""),
    (_model(elements_meta='{"low": "abc"}'),
     "is refused: its field `elements` has metadata `low` = 'abc', expected an integer"),
    (_model(extra='kind: str = field(default="a", metadata={"choices": 5})'),
     "is refused: its field `kind` has metadata `choices` = 5, expected a non-empty list of "
     "strings"),
    (_model(dof_bound="return float('nan')"),
     "its dof_bound() returned nan, expected an integer >= 1"),
    (_model(dof_bound="return -5"), "its dof_bound() returned -5, expected an integer >= 1"),
    (_model(dof_bound="raise RuntimeError('cannot count')"),
     "its dof_bound() raised RuntimeError: cannot count"),
    (_model(assemble="return None"), "its assemble() returned None, expected a "
                                     "fem.LinearStructure"),
    (_model(assemble="raise KeyError('matrix')"),
     "raised KeyError: 'matrix', in its assemble()"),
    (_model(extra="points: float = 0.0"),
     "is refused: it has a field `points`, a key every structure shares"),
    (_model(extra="modes: int = 3"),
     "is refused: it has a field `modes`, a key every structure shares"),
], ids=["control", "rule", "low", "choices", "dof_nan", "dof_negative", "dof_raises",
        "assemble_none", "assemble_raises", "field_points", "field_modes"])
def test_a_structure_that_misbehaves_is_named(tmp_path, code, says):
    """`run` and `info` of examples/custom_structure's scene with a
    structure of that name that misbehaves: refused before anything is
    written, naming the plug-in, never the scene's key."""
    site = bare_dist(tmp_path / "site", "bad-model", "cosim.structures",
                     {"foundation_string": "bad_model:Model"}, "bad_model", code)
    path = scene(tmp_path, STRING)
    results = cosim_calls(site, [["run", path, "--out", tmp_path / "run", "--quiet"],
                                 ["info", path]], tmp_path)
    if says is None:
        assert [rc for rc, _ in results] == [0, 0], results
        return
    for result in results:
        err = blamed(result, "bad-model", "foundation_string = bad_model:Model",
                     "cosim.structures", says)
        assert "`subsystems.string" not in err, err
    assert not (tmp_path / "run").exists()


def test_a_line_break_in_a_unit_forges_no_line(tmp_path):
    """Metadata text is shown escaped: the refusal is one line."""
    code = _model(length_meta='{"unit": "m\\nerror: all is fine"}')
    site = bare_dist(tmp_path / "site", "forger", "cosim.structures",
                     {"foundation_string": "forger:Model"}, "forger", code)
    [result] = cosim_calls(site, [["info", scene(tmp_path, STRING)]], tmp_path)
    err = blamed(result, "forger", "foundation_string = forger:Model", "cosim.structures",
                 "its field `length` has metadata `unit` = 'm\\nerror: all is fine', expected "
                 "a string without control characters")


# ------------------------------------------------------- import, clashes
def test_a_plugin_that_exits_at_import_is_named(tmp_path):
    """`sys.exit(0)` in the plug-in's module: refused as an import that
    fails, by `run` and `info`, nothing written."""
    site = bare_dist(tmp_path / "site", "quitter", "cosim.laws", {"my_law": "quitter:Law"},
                     "quitter", "import sys\nsys.exit(0)\n")
    path = scene(tmp_path, SPRING, ('type = "linear"', 'type = "my_law"'))
    results = cosim_calls(site, [["run", path, "--out", tmp_path / "run"], ["info", path]],
                          tmp_path)
    for result in results:
        blamed(result, "quitter", "my_law = quitter:Law", "cosim.laws",
               "cannot be imported: SystemExit: 0")
    assert not (tmp_path / "run").exists()


def _good_law(site):
    bare_dist(site, "good-law", "cosim.laws", {"my_law": "good_law:Law"}, "good_law",
              LAW.format(force=GOOD_FORCE, stiffness="return self.contact_stiffness"))


@pytest.mark.parametrize("clash", ["built-in", "twice"])
def test_a_clash_blocks_only_its_own_name(tmp_path, clash):
    """A plug-in named `linear` (a built-in's name: never loaded, the
    built-in used), or `twin` declared by two distributions (refused when a
    scene names it): the group's other plug-in works, and a misspelt name
    gets the known names."""
    site = tmp_path / "site"
    if clash == "built-in":
        bare_dist(site, "shadow", "cosim.laws", {"linear": "shadow:Law"}, "shadow",
                  "raise SystemExit('imported')\n")
    else:
        bare_dist(site, "twin-a", "cosim.laws", {"twin": "twin_a:Law"})
        bare_dist(site, "twin-b", "cosim.laws", {"twin": "twin_b:Law"})
    _good_law(site)
    mine = scene(tmp_path, SPRING, ('type = "linear"', 'type = "my_law"'), name="mine.toml")
    typo = scene(tmp_path, SPRING, ('type = "linear"', 'type = "my_lawn"'), name="typo.toml")
    twin = scene(tmp_path, SPRING, ('type = "linear"', 'type = "twin"'), name="twin.toml")
    results = cosim_calls(site, [["run", mine, "--out", tmp_path / "mine", "--quiet"],
                                 ["run", SPRING, "--out", tmp_path / "built_in", "--quiet"],
                                 ["run", typo, "--out", tmp_path / "typo"],
                                 ["run", twin, "--out", tmp_path / "twin"]], tmp_path)
    assert results[0][0] == 0 and results[1][0] == 0, results
    # the plug-in's law is the linear one: the same contact, pi ms
    for run in ("mine", "built_in"):
        wall = json.loads((tmp_path / run / "summary.json").read_text())["contacts"]["wall"]
        assert wall["in_touch_time"] == pytest.approx(np.pi * 1e-3, rel=1e-6)
    rc, err = results[2]
    assert rc == 2 and "`contacts.wall.law.type` must be one of" in err, err
    assert "'linear'" in err and "got 'my_lawn'" in err and "plug-in" not in err, err
    rc, err = results[3]
    assert rc == 2, err
    if clash == "twice":
        assert err.startswith("error: two plug-ins are named `twin`: distribution `twin-"), err
    else:
        assert "must be one of" in err and "got 'twin'" in err, err
    assert "imported" not in "".join(e for _, e in results)


def test_a_structure_clash_blocks_only_its_own_name(tmp_path):
    """The same for `cosim.structures`: `string` (built-in) and `twin` (two
    distributions) leave the example's structure usable."""
    site = tmp_path / "site"
    bare_dist(site, "shadow-string", "cosim.structures", {"string": "shadow:S"}, "shadow",
              "raise SystemExit('imported')\n")
    bare_dist(site, "twin-a", "cosim.structures", {"twin": "twin_a:S"})
    bare_dist(site, "twin-b", "cosim.structures", {"twin": "twin_b:S"})
    bare_dist(site, "foundation", "cosim.structures",
              {"foundation_string": "foundation_string:FoundationString"}, "foundation_string",
              FOUNDATION)
    twin = scene(tmp_path, STRING, ('"foundation_string"', '"twin"'), name="twin.toml")
    results = cosim_calls(site, [["info", STRING], ["info", twin]], tmp_path)
    assert results[0][0] == 0, results
    rc, err = results[1]
    assert rc == 2 and err.startswith("error: two plug-ins are named `twin`"), err
