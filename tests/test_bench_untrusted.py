"""`cosim bench` among files it did not write: links planted in its output
folder and at its cache, cache entries damaged, edited or written for other
inputs, and an output folder that is a file.

The bench is spring_drop's wall as a coupler contact on the cheapest
setting (one Gauss-Seidel step size, one copy; the reference run takes
about half a second); the command runs in the process (``main``).
"""
import hashlib
import importlib.util
import json
import shutil
import warnings
from pathlib import Path

import pytest

import cosim.studies.bench as bench
import cosim.studies.bench_cache as bench_cache
from cosim.cli import main
from cosim.errors import OutputError
from cosim.scene.load import load_scene
from conftest import CASES

SCENE = CASES / "spring_drop.toml"
OVERRIDES = ['contacts.wall.placement="coupler"', "scheme.accept_unsafe_step=true",
             "guard.energy_check=false"]
STRIKE = dict(contact="wall", joint="body/x")
ARGS = ["--contact", "wall", "--joint", "body/x", "--schemes", "gauss_seidel", "--steps",
        "1e-4", "--spread", "1"] + [a for o in OVERRIDES for a in ("--set", o)]


def _bench(out, *extra):
    return main(["bench", str(SCENE), "--out", str(out), *ARGS, *extra])


def _reference(cache, scene=SCENE):
    return bench.reference(scene, overrides=OVERRIDES, cache_dir=cache, **STRIKE)


@pytest.fixture
def runs(monkeypatch):
    """Counts the reference runs (``_run_reference``) while the test goes."""
    real, calls = bench._run_reference, []

    def counted(*a, **k):
        calls.append(a)
        return real(*a, **k)
    monkeypatch.setattr(bench, "_run_reference", counted)
    return calls


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """A cache folder holding the entry of the reference, and the reference
    as that run gave it."""
    cache = tmp_path_factory.mktemp("stored") / "cache"
    return cache, _reference(cache)


@pytest.fixture
def fresh(stored):
    """The reference, as a run gave it."""
    return stored[1]


@pytest.fixture
def cache(stored, tmp_path):
    """A cache folder of the test's own, holding the reference's entry."""
    shutil.copytree(stored[0], tmp_path / "cache")
    return tmp_path / "cache"


def _same(ref, fresh):
    assert ref["count"] == fresh["count"]
    for k in ("peak", "exit_velocity", "energy"):
        assert ref[k] == pytest.approx(fresh[k], rel=1e-9), (k, ref, fresh)


def _entry(cache) -> Path:
    (path,) = Path(cache).glob("*.json")
    return path


def _forge(path, **changes):
    """Change the entry's reference and write a checksum that matches, as
    someone who knows the format would."""
    entry = json.loads(path.read_text())
    entry["reference"].update(changes)
    entry["checksum"] = bench_cache._checksum(entry["key"], entry["reference"])
    path.write_text(json.dumps(entry))


# ------------------------------------------------------------ planted links
def test_links_planted_in_the_output_folder_are_replaced_never_followed(tmp_path, capsys,
                                                                          monkeypatch):
    """bench.tmp, bench.csv, bench.png and reference.json as links to
    victims: the bench writes its own files in their place; every victim
    keeps its content (a link once made the CSV land in a victim), and
    bench.tmp, which the bench does not write, stays the link it was."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    victims = {}
    for name in ("bench.tmp", "bench.csv", "bench.png", "reference.json"):
        victims[name] = tmp_path / f"victim-{name}"
        victims[name].write_text(f"the victim of {name}\n")
        (out / name).symlink_to(victims[name])
    (tmp_path / "absent").mkdir()
    (out / "bench.new").symlink_to(tmp_path / "absent" / "created")
    assert _bench(out) == 0, capsys.readouterr().err
    for name, victim in victims.items():
        assert victim.read_text() == f"the victim of {name}\n", name
    assert not (tmp_path / "absent" / "created").exists()
    assert (out / "bench.tmp").is_symlink()
    for name in ("bench.csv", "reference.json"):
        assert not (out / name).is_symlink() and (out / name).stat().st_size > 0, name
    assert (out / "bench.csv").read_text().startswith("scheme,label,")
    if importlib.util.find_spec("matplotlib") is not None:
        assert (out / "bench.png").read_bytes()[:4] == b"\x89PNG"
    assert not list(out.glob(".*.tmp")) and not (out / ".run.lock").exists()


def test_a_link_at_the_cache_folder_is_refused_before_anything_is_written(tmp_path, capsys,
                                                                          monkeypatch):
    monkeypatch.chdir(tmp_path)
    victim = tmp_path / "victim"
    victim.mkdir()
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / ".bench-cache").symlink_to(victim)
    assert _bench(tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert "runs/.bench-cache: it is a symbolic link" in err and "Traceback" not in err
    assert not list(victim.iterdir())
    assert not (tmp_path / "out").exists()
    with pytest.raises(OutputError, match=r"reference cache .*: it is a symbolic link"):
        _reference(tmp_path / "runs" / ".bench-cache")
    assert not list(victim.iterdir())


def test_a_link_at_a_cache_entry_is_not_read_and_is_replaced(tmp_path, cache, runs, fresh):
    """An entry that is a link to a file holding a valid entry: not read
    (no link is followed), run again, the link replaced and its target
    untouched."""
    entry = _entry(cache)
    target = tmp_path / "elsewhere.json"
    shutil.move(entry, target)
    before = target.read_text()
    entry.symlink_to(target)
    with pytest.warns(UserWarning, match=rf"{entry.name} is a symbolic link: not used"):
        ref = _reference(cache)
    assert len(runs) == 1
    _same(ref, fresh)
    assert not entry.is_symlink() and target.read_text() == before


def test_the_output_folder_as_a_link_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    victim = tmp_path / "victim"
    victim.mkdir()
    (tmp_path / "out").symlink_to(victim)
    assert _bench(tmp_path / "out") == 2
    assert "is a symbolic link" in capsys.readouterr().err
    assert not list(victim.iterdir())


# -------------------------------------------------------------- --out FILE
def test_out_naming_a_file_is_a_clear_error(tmp_path, capsys, monkeypatch):
    """`--out FILE` once gave a FileExistsError traceback: exit 2, the file
    named and left as it was, nothing run."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file").write_text("mine\n")
    assert _bench(tmp_path / "file") == 2
    cap = capsys.readouterr()
    assert "file: it exists and is not a folder" in cap.err and "Traceback" not in cap.err
    assert "paper_rk45" not in cap.out
    assert (tmp_path / "file").read_text() == "mine\n"
    assert not (tmp_path / "runs").exists()


def test_a_busy_output_folder_is_refused(tmp_path, capsys, monkeypatch):
    """The bench holds its --out folder's lock: a second bench into it is
    refused, and leaves its files alone."""
    from cosim.io.rundir import OutputFolder
    monkeypatch.chdir(tmp_path)
    with OutputFolder(tmp_path / "out"):
        assert _bench(tmp_path / "out") == 2
    assert "in use by another run" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == []


def test_a_bench_that_fails_leaves_no_folder_it_made(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert _bench(tmp_path / "out", "--contact", "nowhere") == 2
    assert "nowhere" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------- the cache
def test_an_entry_is_used_only_when_fit(tmp_path, runs, fresh):
    """The first call runs the reference and stores it; the second reads it
    (no run); an entry whose checksum matches is used as it is (the trust
    model: the cache folder is the user's own)."""
    cache = tmp_path / "cache"
    _same(_reference(cache), fresh)
    assert len(runs) == 1
    _same(_reference(cache), fresh)
    assert len(runs) == 1
    _forge(_entry(cache), peak=0.5)
    assert _reference(cache)["peak"] == 0.5
    assert len(runs) == 1


def test_a_doctored_number_is_detected_and_run_again(tmp_path, cache, runs, fresh, capsys,
                                                     monkeypatch):
    """A number edited in the entry (its checksum left as it was) once
    changed the bench's reference, exit 0: now a warning names the file, the
    reference is run again (equal to a fresh one) and the entry replaced."""
    entry = _entry(cache)
    doctored = json.loads(entry.read_text())
    doctored["reference"]["peak"] *= 2
    entry.write_text(json.dumps(doctored))
    with pytest.warns(UserWarning, match=rf"the bench cache entry .*{entry.name} does not "
                                         rf"match its checksum .*: not used; the reference is "
                                         rf"run again"):
        ref = _reference(cache)
    assert len(runs) == 1
    _same(ref, fresh)
    assert bench.entry_problem(json.loads(entry.read_text()), doctored["key"]) is None
    # the command says so on stderr and reports the fresh reference
    monkeypatch.chdir(tmp_path)
    runs_cache = tmp_path / "runs" / ".bench-cache"
    runs_cache.mkdir(parents=True)
    shutil.copy(entry, runs_cache / entry.name)
    entry = runs_cache / entry.name
    entry.write_text(json.dumps(doctored))
    assert _bench(tmp_path / "out") == 0
    cap = capsys.readouterr()
    assert f"warning: the bench cache entry runs/.bench-cache/{entry.name} does not match " \
           f"its checksum" in cap.err
    stored = json.loads((tmp_path / "out" / "reference.json").read_text())
    _same(stored, fresh)


BAD = {
    "a JSON list": ("[1, 2, 3]", r"holds list \[1, 2, 3\], not a cache entry"),
    "a JSON string": ('"reference"', r"holds str 'reference', not a cache entry"),
    "a truncated file": (None, r"is not JSON"),
    "deep nesting": ("[" * 60000, r"is not JSON \(maximum recursion depth"),
    "too large": (" " * bench.CACHE_MAX_BYTES + "{}", r"holds more than 65536 bytes"),
    "not UTF-8": (b"\xff\xfe{}", r"is not JSON"),
    "another layout": ('{"count": 1, "peak": 0.001}', r"holds the keys \['count', 'peak'\]"),
    "an empty file": ("", r"is not JSON"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_malformed_entry_is_run_again_with_a_warning(case, cache, runs, fresh):
    """A JSON list there once gave a TypeError traceback."""
    entry = _entry(cache)
    content, message = BAD[case]
    if content is None:
        content = entry.read_text()[:len(entry.read_text()) // 2]
    if isinstance(content, bytes):
        entry.write_bytes(content)
    else:
        entry.write_text(content)
    with pytest.warns(UserWarning, match=rf"{entry.name} {message}"):
        ref = _reference(cache)
    assert len(runs) == 1
    _same(ref, fresh)
    _same(json.loads(entry.read_text())["reference"], fresh)


WRONG = {
    "peak as text": (dict(peak="0.001"), r"`reference.peak` is str '0.001', not a number"),
    "peak infinite": (dict(peak=float("inf")), r"`reference.peak` is inf, not a finite"),
    "peak NaN": (dict(peak=float("nan")), r"`reference.peak` is nan, not a finite"),
    "count a boolean": (dict(count=True), r"`reference.count` is bool True, not a number"),
    "count negative": (dict(count=-1), r"`reference.count` is -1, not a count"),
    "count fractional": (dict(count=1.5), r"`reference.count` is 1.5, not a count"),
    "a field missing": (dict(cpu_time_s=None), r"holds a `reference` of the fields"),
    "a list of numbers": (dict(exit_velocity=[1.0]), r"`reference.exit_velocity` is list"),
}


@pytest.mark.parametrize("case", list(WRONG))
def test_an_entry_of_the_wrong_shape_is_run_again_even_with_its_checksum(case, cache, runs,
                                                                         fresh):
    """Fields of the wrong type, sign or finiteness are refused before the
    checksum is looked at: a checksum that matches makes no bad number
    usable."""
    entry = _entry(cache)
    change, message = WRONG[case]
    data = json.loads(entry.read_text())
    for k, v in change.items():
        if v is None:
            del data["reference"][k]
        else:
            data["reference"][k] = v
    data["checksum"] = bench_cache._checksum(data["key"], data["reference"])
    entry.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match=rf"{entry.name} {message}"):
        ref = _reference(cache)
    assert len(runs) == 1
    _same(ref, fresh)


def test_an_entry_of_another_cosim_version_is_not_used(cache, runs, fresh, monkeypatch):
    """An entry whose checksum matches, written by another version: another
    name, so not found (run again); copied to this version's name, named in
    a warning and run again."""
    old = _entry(cache)
    _forge(old, peak=0.5)
    monkeypatch.setattr(bench_cache, "__version__", "0.0.1")
    _same(_reference(cache), fresh)
    assert len(runs) == 1
    (new,) = set(cache.glob("*.json")) - {old}
    shutil.copy(old, new)
    with pytest.warns(UserWarning, match=rf"{new.name} was written by cosim '\S+', not by this "
                                         rf"version \(0.0.1\)"):
        _same(_reference(cache), fresh)
    assert len(runs) == 2


def test_an_entry_for_other_scene_content_is_not_used(tmp_path, runs, fresh):
    """The scene file changed (here a comment added, the table the same):
    the entry written before is not used, even where its name is taken."""
    scene = tmp_path / "spring_drop.toml"
    shutil.copy(SCENE, scene)
    cache = tmp_path / "cache"
    _reference(cache, scene)
    old = _entry(cache)
    _forge(old, peak=0.5)
    scene.write_text(scene.read_text() + "\n# edited\n")
    _same(_reference(cache, scene), fresh)
    assert len(runs) == 2
    (new,) = set(cache.glob("*.json")) - {old}
    shutil.copy(old, new)
    with pytest.warns(UserWarning, match=rf"{new.name} was written for other content of "
                                         rf"scene"):
        _same(_reference(cache, scene), fresh)
    assert len(runs) == 3


def test_an_entry_for_other_settings_is_not_used(tmp_path, runs):
    """Another contact's or variant's entry, copied to this one's name."""
    cache = tmp_path / "cache"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # options the monolithic scheme ignores
        scene = load_scene(SCENE, None, OVERRIDES, "monolithic")
    key = bench.cache_key(scene, None, "wall", "body/x")
    other = bench.cache_key(scene, None, "wall", "body/y")
    ref = {"count": 1, "peak": 1e-3, "exit_velocity": 1.0, "energy": 0.0, "cpu_time_s": 0.1}
    assert bench.entry_problem(bench.cache_entry(key, ref), key) is None
    assert bench.entry_problem(bench.cache_entry(other, ref), key) == \
        "was written for other inputs (its key differs in ['joint'])"
    assert not cache.exists() and not runs


@pytest.fixture(scope="module")
def two_fmus(tmp_path_factory):
    """Two co-simulation FMUs of the arm that differ in content (with and
    without state saving), built as examples/fmu/build.py builds them."""
    pytest.importorskip("fmpy", reason="FMPy is not installed (the `fmi` extra)")
    root = Path(__file__).resolve().parent.parent
    spec = importlib.util.spec_from_file_location("fmu_build",
                                                  root / "examples" / "fmu" / "build.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    cc = build.find_compiler()
    if cc is None:
        pytest.skip("no C compiler found ($CC, gcc or cc): the test FMU cannot be built")
    out = tmp_path_factory.mktemp("fmu")
    return root / "examples" / "fmu" / "arm_on_beam.toml", [
        build.build_fmu(out, 2, state, cc) for state in (True, False)]


def test_the_key_holds_the_content_of_every_fmu_the_scene_names(tmp_path, two_fmus):
    """The same scene and path, the FMU file replaced: another key, and an
    entry of the old one names the FMU's key path as what changed."""
    scene_file, fmus = two_fmus
    fmu = tmp_path / "arm.fmu"

    def key():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = load_scene(scene_file, None, [f"subsystems.arm.path={fmu}"], "monolithic")
        return scene, bench.cache_key(scene, None, "C", "arm/q1")
    shutil.copy(fmus[0], fmu)
    scene, before = key()
    assert before["files"]["subsystems.arm.path"] == hashlib.sha256(
        fmu.read_bytes()).hexdigest()
    shutil.copy(fmus[1], fmu)
    scene, after = key()
    assert after["table"] == before["table"] and after["files"]["scene"] == \
        before["files"]["scene"]
    assert bench.entry_name(scene, None, after) != bench.entry_name(scene, None, before)
    ref = {"count": 1, "peak": 1e-3, "exit_velocity": 1.0, "energy": 0.0, "cpu_time_s": 0.1}
    assert bench.entry_problem(bench.cache_entry(before, ref), after) == \
        "was written for other content of subsystems.arm.path (its SHA-256 differs)"
