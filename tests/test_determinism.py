"""The same scene and options give the same files, byte for byte.

``summary.json`` differs only in ``cpu_time_s`` (the one timing it holds);
``series.npz`` is the same file: its members are stored in a fixed order with
a fixed date, and the numbers do not depend on the run's wall clock, on the
size of the chunks the recorder streams, or on whether the series were
streamed to disk or kept in memory.

Every comparison here is of the same computation run twice (the same code on
the same machine, the numbers only stored otherwise), so bit identity is the
claim.  Two different computations of a number are compared within a bound
in ulps instead (tests/ulps.py).
"""
import json

import numpy as np
import pytest

from conftest import CASES
import cosim
from cosim.core import series as series_mod
from cosim.core.series import SeriesFile

#: summary keys that measure the run rather than describe its outcome
TIMINGS = ("cpu_time_s",)


def outcome(summary_path) -> dict:
    s = json.loads(summary_path.read_text())
    for key in TIMINGS:
        assert key in s
        s.pop(key)
    # the estimate's companions, when they ran, have their own timings
    acc = s.get("accuracy", {})
    acc.get("companion", {}).pop("cpu_time_s", None)
    for comp in acc.get("companions", []):
        comp.pop("cpu_time_s", None)
    return s


def run(tmp_path, name, scene, variant=None, overrides=()):
    out = tmp_path / name
    cosim.simulate(cosim.load_scene(CASES / scene, variant, overrides), out=out)
    return out


@pytest.mark.parametrize("scene,variant,overrides", [
    ("three_mass.toml", "f100", ["t_end=0.12"]),      # C's first contacts (from 0.103 s)
    ("rod_impact.toml", None, ["subsystems.rod.elements=40"]),   # a structure
])
def test_two_runs_write_identical_files(tmp_path, scene, variant, overrides):
    a = run(tmp_path, "a", scene, variant, overrides)
    b = run(tmp_path, "b", scene, variant, overrides)
    assert (a / "series.npz").read_bytes() == (b / "series.npz").read_bytes()
    assert outcome(a / "summary.json") == outcome(b / "summary.json")
    assert (a / "scene.toml").read_bytes() == (b / "scene.toml").read_bytes()
    s = outcome(a / "summary.json")
    assert s["status"] == "finished" and sum(c["count"] for c in s["contacts"].values()) > 0


def test_streamed_and_in_memory_series_are_the_same_file(tmp_path, monkeypatch):
    """Streaming in chunks of 64 samples (several chunks), or keeping the
    series in memory and writing them with ``write_outputs``, gives the same
    bytes; the run directory keeps no spool."""
    monkeypatch.setattr(series_mod, "CHUNK_BYTES", 64)      # 64 rows a chunk at least
    scene = cosim.load_scene(CASES / "spring_drop.toml", "kelvin_voigt")
    streamed = cosim.simulate(scene, out=tmp_path / "s")
    memory = cosim.simulate(scene)
    assert isinstance(streamed.series, SeriesFile) and isinstance(memory.series, dict)
    n = len(memory.t)
    assert n > 3 * 64                                        # several chunks
    cosim.write_outputs(memory, tmp_path / "m", scene)
    assert ((tmp_path / "s" / "series.npz").read_bytes()
            == (tmp_path / "m" / "series.npz").read_bytes())
    assert outcome(tmp_path / "s" / "summary.json") == outcome(tmp_path / "m" / "summary.json")
    assert list(streamed.series) == list(memory.series)
    for key, value in memory.series.items():
        got = streamed.series[key]
        assert got.dtype == value.dtype and np.array_equal(got, value), key
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == [
        "scene.toml", "series.npz", "summary.json"]


def test_chunk_size_does_not_change_the_numbers(tmp_path, monkeypatch):
    scene = cosim.load_scene(CASES / "spring_drop.toml")
    whole = cosim.simulate(scene)
    monkeypatch.setattr(series_mod, "CHUNK_BYTES", 1)
    small = cosim.simulate(scene)
    assert list(small.series) == list(whole.series)
    for key in whole.series:
        assert np.array_equal(small.series[key], whole.series[key]), key


def test_npz_bytes_depend_on_the_data_only(tmp_path):
    arrays = {"t": np.linspace(0.0, 1.0, 11), "mode/x": np.arange(11)}
    series_mod.write_npz(tmp_path / "a.npz", arrays)
    series_mod.write_npz(tmp_path / "b.npz", arrays)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    series_mod.write_npz(tmp_path / "c.npz", {**arrays, "t": arrays["t"] + 1e-9})
    assert (tmp_path / "c.npz").read_bytes() != (tmp_path / "a.npz").read_bytes()
    with np.load(tmp_path / "a.npz") as npz:
        assert npz.files == ["t", "mode/x"]
        assert np.array_equal(npz["mode/x"], arrays["mode/x"])
        assert npz["mode/x"].dtype == arrays["mode/x"].dtype
