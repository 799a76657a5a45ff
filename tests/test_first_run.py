"""First runs count: a process's first run pays nothing one-time inside its
solve (the window ``cpu_time_s`` measures, :func:`cosim.scene.run.simulate`).

What a run needs once (the sides' compiled kernels built, the modules of the
loop that takes it, the recorder's rows and spool) is done by
:meth:`CouplingScheme.prepare <cosim.core.schemes.base.CouplingScheme.prepare>`
and :meth:`Recorder.prepare <cosim.core.recorder.Recorder.prepare>` before the
clock starts.  Each case runs one scene in a fresh interpreter, as `cosim run`
does, and reads back the modules loaded between the recorder's preparation
(the last thing before the clock) and its ``finish`` (the clock read): a
behaviour, not a timing.  ``benchmarks/scenes.py --first-run`` measures what it
saves.

And a compiled kernel that was built but does not fit the modules it was
built with (Cython's "size changed, may indicate binary incompatibility") is a
broken build: the run stops with an error that says what rebuilds it, never
runs on past it on the numpy reference (CI must test the compiled code).
"""
import json
import subprocess
import sys

import pytest

from conftest import CASES, ROOT
from cosim.sides.kernel import kernel_choice

SCRIPT = """
import json, sys
import cosim
from cosim.core.recorder import Recorder
from cosim.core.schemes.base import CoSimulationScheme
if sys.argv[6] == "unprepared":          # the check below could fail: no preparation
    CoSimulationScheme.prepare = lambda self, system, t_end, recorder: None
marks = {}
prepare, finish = Recorder.prepare, Recorder.finish
def prepared(self):
    prepare(self)
    marks["start"] = set(sys.modules)
def finishing(self, *args, **kw):
    marks["loaded"] = sorted(set(sys.modules) - marks["start"])
    return finish(self, *args, **kw)
Recorder.prepare, Recorder.finish = prepared, finishing
scene = cosim.load_scene(sys.argv[1], sys.argv[2] or None, scheme=sys.argv[3] or None,
                         overrides=json.loads(sys.argv[4]))
res = cosim.simulate(scene, estimate=False, out=sys.argv[5])
print(json.dumps({"status": res.summary["status"], "loaded": marks["loaded"]}))
"""

#: each way a run is taken: the sampled path (spring_drop, manipulator_wall),
#: the compiled loop in blocks (three_mass f100, ground_multicontact), with a
#: following contact (beam_impact), the Python loop (multirate: ms0.1), the
#: implicit iterations and the monolithic solver over compiled faces
RUNS = [("spring_drop", None, None, ()),
        ("manipulator_wall", "mu0.03", None, ()),
        ("manipulator_wall", "mu0.03", "monolithic", ()),
        ("three_mass", "f100", None, ()),
        ("three_mass", "f100", "monolithic", ()),
        ("three_mass", "ms0.1", None, ()),
        ("ground_multicontact", None, None, ()),
        ("three_mass", "f100", "implicit", ()),
        ("beam_impact", None, None, ())]
#: and the other shipped scenes and schemes (slow: their structures build
#: for seconds; the same loops as above)
MORE = [("brachiation", None, None, ("t_end=0.1",)),
        ("spring_drop", "kelvin_voigt", "monolithic", ()),
        ("manipulator_wall", "penalty", None, ()),
        ("rod_impact", None, None, ()),
        ("rod_impact", None, "implicit", ()),
        ("ground_multicontact_strike", None, None, ()),
        ("beam_impact", None, "monolithic", ()),
        ("beam_impact_2d", None, None, ()),
        ("beam_with_holes", None, None, ()),
        ("brachiation", None, "monolithic", ("t_end=0.02",)),
        ("brachiation", "rigid_cable", None, ("t_end=0.1",))]


def window(tmp_path, name, variant, scheme, over, mode="prepared"):
    """The status of a fresh process's run and the modules it loaded inside
    its solve."""
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(CASES / f"{name}.toml"), variant or "", scheme or "",
         json.dumps(list(over)), str(tmp_path / "run"), mode],
        cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.splitlines()[-1])


@pytest.mark.parametrize("name,variant,scheme,over", RUNS + [
    pytest.param(*r, marks=pytest.mark.slow) for r in MORE],
    ids=[f"{n}-{v or 'default'}-{s or 'scheme'}" for n, v, s, _ in RUNS + MORE])
def test_a_first_run_imports_nothing_inside_its_solve(tmp_path, name, variant, scheme, over):
    got = window(tmp_path, name, variant, scheme, over)
    assert got["status"] == "finished"
    assert got["loaded"] == [], f"modules loaded inside the solve: {got['loaded']}"


@pytest.mark.skipif(kernel_choice() == "numpy", reason="the compiled loop's modules are the case")
def test_without_its_preparation_a_first_run_loads_the_loop_inside_its_solve(tmp_path):
    """The check above sees an import inside the solve: three_mass f100's
    compiled loop, its block filler and the structures' kernels load there
    when nothing prepares the run."""
    got = window(tmp_path, "three_mass", "f100", None, (), "unprepared")
    assert got["status"] == "finished"
    assert {"cosim.core.schemes._driver", "cosim.core.schemes._driver_block",
            "cosim.sides._structure_step"} <= set(got["loaded"]), got["loaded"]


# ------------------------------------------------------ a kernel built wrong
#: what Cython raises at import where a shared type's size is not the one a
#: kernel was compiled against
MISMATCH = ("cosim.core._stacked.FaceTable size changed, may indicate binary "
            "incompatibility. Expected 40 from C header, got 48 from PyObject")


def _stale(monkeypatch, stale):
    """Make importing the modules ``stale`` raise as a mismatched build does."""
    import importlib

    from cosim.core import kernel_import
    real = importlib.import_module

    def fake(name, package=None):
        if name in stale:
            raise ValueError(MISMATCH)
        return real(name, package)

    monkeypatch.setattr(kernel_import.importlib, "import_module", fake)


def test_a_kernel_built_against_other_declarations_stops_with_the_rebuild(monkeypatch):
    from cosim.errors import KernelBuildError
    from cosim.sides import kernel
    from cosim.sides.kernel import compiled_module
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    monkeypatch.setattr(kernel, "_missing_said", set())    # this test's warning is its own
    _stale(monkeypatch, {"cosim.sides._structure_step"})
    with pytest.raises(KernelBuildError) as err:
        compiled_module("_structure_step")
    text = str(err.value)
    assert "`cosim.sides._structure_step`" in text and "size changed" in text
    assert "python setup.py build_ext --inplace" in text and "pip install ." in text
    # not one that is missing: that one falls back to the reference, said once
    monkeypatch.setattr(sys.modules["cosim.core.kernel_import"].importlib, "import_module",
                        lambda name, package=None: (_ for _ in ()).throw(ImportError(name)))
    assert compiled_module("_structure_step") is None


def test_cosim_run_says_the_broken_build_and_runs_nothing(monkeypatch, tmp_path, capsys):
    """`cosim run` prints the error (exit 2, no traceback) and writes no
    series: the loop's module is found stale before the clock starts."""
    from cosim.cli import main
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    _stale(monkeypatch, {"cosim.core.schemes._driver"})
    monkeypatch.delitem(sys.modules, "cosim.core.schemes._driver", raising=False)   # as fresh
    out = tmp_path / "run"
    code = main(["run", str(CASES / "three_mass.toml"), "--variant", "f100", "--quiet",
                 "--no-estimate", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "error: the compiled kernel `cosim.core.schemes._driver` was built but does not fit" \
        in err and "Traceback" not in err
    assert not out.exists()              # the folder it made goes with it, empty
