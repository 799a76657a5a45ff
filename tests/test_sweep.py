"""cosim sweep: the grid, run directories and resume, failures, one table whether
the points run here, on a process pool or on Dask, and the impact regimes of
CASES.md section 5 as the chain mass falls."""
import csv
import io
import json
import math
import subprocess
import sys
import warnings

import pytest

from conftest import CASES, ROOT
from sweeping import Events
from cosim import cli
from cosim.studies import sweep as sw
from cosim.studies.metrics import impact_regime

THREE_MASS = CASES / "three_mass.toml"
SPRING_DROP = CASES / "spring_drop.toml"
STUDIES = ROOT / "studies"

# C strikes the chain 22 ms after the start when the arm starts at 0.45 rad (at
# 2 rad it strikes at 0.103 s), so short runs see contacts of C.
NEAR = {"subsystems.robot.bodies.arm.joint.q0": [0.45]}


def table_without_timing(path) -> list[list[str]]:
    """The CSV's cells, the columns that measure the machine left out."""
    rows = list(csv.reader(io.StringIO(path.read_text())))
    keep = [i for i, c in enumerate(rows[0]) if c not in sw.TIMING_COLUMNS]
    return [[r[i] for i in keep] for r in rows]


# ------------------------------------------------------------------ the grid
def test_values_split_at_top_level_commas_only():
    assert sw.split_values("1.6e5, 3.2e5") == ["1.6e5", "3.2e5"]
    assert sw.split_values("[0.1, 0.1],[0.2,0.2]") == ["[0.1, 0.1]", "[0.2,0.2]"]
    assert sw.split_values('"a,b",\'c\',{ x = 1, y = 2 }') == ['"a,b"', "'c'",
                                                              "{ x = 1, y = 2 }"]
    for bad in ("[1, 2", '"a', "1,,2", "1]"):
        with pytest.raises(ValueError):
            sw.split_values(bad)


def test_grid_option_reads_toml_values():
    key, values = sw.parse_grid_option("contacts.C.law.contact_stiffness=1.6e5,16000000")
    assert key == "contacts.C.law.contact_stiffness" and values == [160000.0, 16000000]
    assert sw.parse_grid_option("subsystems.chain.masses=[0.1,0.1,0.1],[0.2,0.2,0.2]")[1] == [
        [0.1, 0.1, 0.1], [0.2, 0.2, 0.2]]
    assert sw.parse_grid_option('contacts.C.placement="coupler",embedded')[1] == [
        "coupler", "embedded"]


def test_grid_order_and_point_names():
    pts = sw.grid_points(["f1", "f100"], {"t_end": [0.03, 0.04], "scheme.macro_step": [1e-3]})
    assert [(p.variant, dict(p.params)["t_end"]) for p in pts] == [
        ("f1", 0.03), ("f1", 0.04), ("f100", 0.03), ("f100", 0.04)]
    assert [p.index for p in pts] == [0, 1, 2, 3]
    assert pts[1].name == "f1,t_end=0.04,scheme.macro_step=0.001"
    assert pts[1].overrides == [(["t_end"], 0.04), (["scheme", "macro_step"], 0.001)]
    # the name depends on the parameters alone
    again = sw.grid_points(["f100"], {"t_end": [0.04], "scheme.macro_step": [0.001]})
    assert again[0].name == pts[3].name
    # values that need other characters get a hash, and never collide
    names = [p.name for p in sw.grid_points(None, {"a": [[1, 2], "1_2", "[1,2]", "x/y"]})]
    assert len(set(names)) == 4
    assert all("/" not in n and "[" not in n and "," not in n for n in names)
    assert sw.grid_points()[0].name == "default"
    with pytest.raises(ValueError, match="repeats"):
        sw.grid_points(["f1", "f1"])
    with pytest.raises(ValueError, match="list of values"):
        sw.grid_points(None, {"t_end": "0.1"})


def test_flatten_joins_keys_with_dots():
    flat = sw.flatten({"a": 1, "contacts": {"C": {"count": 2, "intervals": [[0, 1]]}}})
    assert flat == {"a": 1, "contacts.C.count": 2, "contacts.C.intervals": [[0, 1]]}


# ----------------------------------------------------------------- regimes
def _run(intervals, t, rate):
    """A made-up run's summary and series, and the contact and joint to read:
    names of no shipped scene, since the regime reads whichever it is told."""
    return ({"contacts": {"strike": {"intervals": intervals, "count": len(intervals)}}},
            {"t": t, "dq/hammer/swing": rate}, "strike", "hammer/swing")


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_regime_is_what_the_striker_does_in_its_first_contact(sign):
    """The rule, on made-up runs, whichever way the striker's joint counts."""
    t = [0.0, 1.0, 2.0, 3.0, 4.0]
    down = [sign * v for v in (-10.0, -10.0, -6.0, -3.0, 2.0)]    # still coming at release
    back = [sign * v for v in (-10.0, -10.0, 4.0, 4.0, 4.0)]      # turned back at release
    r = impact_regime(*_run([[1.0, 2.0]], t, back))
    assert r["regime"] == "backward"
    assert r["rate_at_touch"] == sign * -10.0 and r["rate_at_release"] == sign * 4.0
    assert impact_regime(*_run([[1.0, 2.0], [2.5, 3.0]], t, back))["regime"] == "backward+"
    r = impact_regime(*_run([[1.0, 2.0], [2.5, 3.0]], t, down))
    assert r["regime"] == "forward" and r["exit_velocity"] == sign * -3.0
    assert impact_regime(*_run([], t, down))["regime"] == "none"
    r = impact_regime(*_run([[1.0, 4.0]], t, down))
    assert r["regime"] == "open-ended" and math.isnan(r["rate_at_release"])


def test_impact_regime_lives_in_metrics_and_the_sweep_still_offers_it():
    from cosim.studies import metrics
    assert sw.impact_regime is metrics.impact_regime is impact_regime
    assert "impact_regime" in metrics.__all__


def test_chain_mass_sweep_gives_the_three_regimes(tmp_path):
    """CASES.md section 5, from the runs alone: the heaviest chains throw the arm
    back in one contact, 1.6 kg turns it back so slowly that the top mass
    catches it, the lightest are pushed ahead of it in a train of contacts.
    C's contacts end by 0.128 s, so the runs stop at 0.14 s (the study runs
    to the scene's 0.25 s: `test_chain_mass_study_file`)."""
    study = sw.load_study(STUDIES / "fig11_chain_mass.toml")
    rows = sw.sweep(study.scene, variants=study.variants, grid={"t_end": [0.14]}, workers=2,
                    out=tmp_path)
    found = {r["variant"]: r["impact.regime"] for r in rows}
    assert found == {"ms6.4": "backward", "ms3.2": "backward", "ms1.6": "backward+",
                     "ms0.8": "forward", "ms0.4": "forward", "ms0.2": "forward",
                     "ms0.1": "forward", "ms0.05": "forward"}
    count = {r["variant"]: r["contacts.C.count"] for r in rows}
    assert count["ms6.4"] == count["ms3.2"] == 1 and count["ms1.6"] == 2
    assert count["ms0.05"] > count["ms0.2"] > count["ms0.8"] > 2
    # every chain throws the arm back in the end
    assert all(r["impact.exit_velocity"] > 0 for r in rows)


@pytest.mark.slow
def test_chain_mass_study_file(tmp_path):
    """The study as shipped (full length), with its table and plot."""
    rows, png = sw.run_study(sw.load_study(STUDIES / "fig11_chain_mass.toml"),
                             out=tmp_path, workers=2)
    regimes = [r["impact.regime"] for r in rows]
    assert regimes == ["forward"] * 5 + ["backward+", "backward", "backward"]
    assert png.stat().st_size > 10_000


def test_study_files_load():
    fig8 = sw.load_study(STUDIES / "fig8_stiffness.toml")
    assert fig8.scene.resolve() == THREE_MASS.resolve()
    f = [v * fig8.x_scale for v in fig8.grid[fig8.x]]
    assert f == pytest.approx([1, 2, 3, 4, 6, 10, 20, 40, 100], rel=1e-12)
    fig11 = sw.load_study(STUDIES / "fig11_chain_mass.toml")
    assert fig11.scene.resolve() == THREE_MASS.resolve()
    assert len(sw.grid_points(fig11.variants, fig11.grid)) == 8


def test_stiffness_study_ends_of_the_range(tmp_path):
    """Figure 8's ends: one contact of C at f = 1, nine at f = 100."""
    fig8 = sw.load_study(STUDIES / "fig8_stiffness.toml")
    ends = [fig8.grid[fig8.x][0], fig8.grid[fig8.x][-1]]
    rows = sw.sweep(fig8.scene, variants=fig8.variants, grid={fig8.x: ends, "t_end": [0.14]},
                    workers=2)
    assert [r["contacts.C.count"] for r in rows] == [1, 9]


def test_bad_study_file_names_the_key(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('scene = "x.toml"\nvariants = "f1"\n')
    with pytest.raises(sw.SceneError, match="variants"):
        sw.load_study(p)
    p.write_text('scene = "x.toml"\nsteps = 3\n')
    with pytest.raises(sw.SceneError, match="steps"):
        sw.load_study(p)


# ----------------------------------------------------- where the points run
def test_one_process_a_pool_and_dask_give_the_same_table(tmp_path):
    distributed = pytest.importorskip("distributed")
    grid = {**NEAR, "t_end": [0.03, 0.04]}
    kw = dict(variants=["f1", "f100"], grid=grid)
    here = sw.sweep(THREE_MASS, workers=1, out=tmp_path / "here", **kw)
    pool = sw.sweep(THREE_MASS, workers=2, out=tmp_path / "pool", **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        dask = sw.sweep(THREE_MASS, scheduler=cluster.scheduler_address,
                        out=tmp_path / "dask", **kw)
    memory = sw.sweep(THREE_MASS, workers=1, **kw)           # nothing written
    expected = table_without_timing(tmp_path / "here" / sw.TABLE)
    assert len(expected) == 5
    # every point runs the same code (the same kernel, the same numpy) here
    # and in the workers, which inherit this environment: the same
    # computation, so the same table bit for bit; a difference means a point
    # ran another code path (e.g. another cosim found first on sys.path)
    assert table_without_timing(tmp_path / "pool" / sw.TABLE) == expected
    assert table_without_timing(tmp_path / "dask" / sw.TABLE) == expected

    def strip(rows):
        return [{k: v for k, v in r.items() if k not in sw.TIMING_COLUMNS} for r in rows]
    assert strip(pool) == strip(dask) == strip(memory) == strip(here)
    # C struck in every point; f100 rebounds where f1 stays in touch
    assert [r["contacts.C.count"] for r in here] == [1, 1, 4, 8]
    assert [r["impact.regime"] for r in here][:2] == ["open-ended"] * 2
    # the run directories hold what `cosim run` writes
    d = tmp_path / "dask" / here[3]["point"]
    assert {p.name for p in d.iterdir()} == {"summary.json", "series.npz", "scene.toml",
                                             "point.json"}
    assert json.loads((d / "summary.json").read_text())["contacts"]["C"]["count"] == 8


def test_table_reads_back(tmp_path):
    rows = sw.sweep(THREE_MASS, variants=["f100"], grid={**NEAR, "t_end": [0.03]},
                    out=tmp_path)
    back = sw.read_table(tmp_path / sw.TABLE)
    # empty text reads back as None; NaN compares through JSON
    assert json.dumps(back) == json.dumps([{k: (v if v != "" else None)
                                            for k, v in rows[0].items()}])
    assert list(back[0])[:6] == ["set.subsystems.robot.bodies.arm.joint.q0", "set.t_end",
                                 "variant", "point", "status", "message"]
    # the grid's t_end is what was asked, the summary's what the run reached
    assert back[0]["set.t_end"] == 0.03 and back[0]["t_end"] == pytest.approx(0.03, abs=1e-12)


# ---------------------------------------------------------- resume, failures
def test_resume_skips_the_points_done(tmp_path):
    grid = {**NEAR, "t_end": [0.03, 0.035]}
    first = Events()
    sw.sweep(THREE_MASS, variants=["f100"], grid=grid, out=tmp_path, progress=first)
    assert len(first.ran) == 2 and not first.skipped
    stamps = {p: (tmp_path / p / "summary.json").stat().st_mtime_ns for p in first.ran}

    grid["t_end"].append(0.04)
    again = Events()
    rows = sw.sweep(THREE_MASS, variants=["f100"], grid=grid, out=tmp_path, progress=again)
    assert again.skipped == first.ran and len(again.ran) == 1
    assert {p: (tmp_path / p / "summary.json").stat().st_mtime_ns for p in first.ran} == stamps
    assert [r["set.t_end"] for r in rows] == [0.03, 0.035, 0.04]
    assert all(r["status"] == "finished" for r in rows)
    assert len(sw.read_table(tmp_path / sw.TABLE)) == 3

    # an interrupted point (its summary cut short) runs again
    cut = tmp_path / rows[0]["point"] / "summary.json"
    cut.write_text(cut.read_text()[:100])
    third = Events()
    sw.sweep(THREE_MASS, variants=["f100"], grid=grid, out=tmp_path, progress=third)
    assert third.ran == [rows[0]["point"]]

    # another scheme is another sweep: nothing is skipped
    other = Events()
    with warnings.catch_warnings():             # the scene's options for other schemes:
        warnings.simplefilter("error")          # no fault of the scene, no warning
        sw.sweep(THREE_MASS, variants=["f100"], grid=grid, out=tmp_path, scheme="jacobi",
                 progress=other)
    assert len(other.ran) == 3 and not other.skipped


def test_the_sweeps_train_counts_hold_under_round_off():
    """The counts the sweep tests read off f100's train with the arm started
    near (4 contacts of C by 0.03 s, 8 by 0.04 s) hold for the round-off
    copies of those points (measured over 5 copies; 0.05 s a run)."""
    import cosim
    from roundoff import assert_robust

    (key, (q0,)), = NEAR.items()
    for t_end, count in ((0.03, 4), (0.04, 8)):
        scene = cosim.load_scene(THREE_MASS, "f100", [f"{key}={q0}", f"t_end={t_end}"])
        assert_robust(scene, lambda r: (r.status, r.summary["contacts"]["C"]["count"]),
                      ("finished", count))


def test_failing_points_are_recorded_and_the_others_complete(tmp_path):
    """A step the pre-flight check refuses, a scene value the loader refuses and
    an implicit step that does not converge: each is a row with its reason."""
    grid = {**NEAR, "t_end": [0.03],
            "contacts.C.placement": ["embedded", "coupler"]}
    ev = Events()
    rows = sw.sweep(THREE_MASS, variants=["f1", "f100"], grid=grid, workers=2, out=tmp_path,
                    progress=ev)
    status = {(r["variant"], r["set.contacts.C.placement"]): r["status"] for r in rows}
    assert status == {("f1", "embedded"): "finished", ("f1", "coupler"): "finished",
                      ("f100", "embedded"): "finished", ("f100", "coupler"): "refused"}
    refused = rows[3]
    assert "largest safe macro step" in refused["message"]
    assert "contacts.C.count" not in refused
    assert rows[2]["contacts.C.count"] == 4
    assert json.loads((tmp_path / refused["point"] / "point.json").read_text())[
        "status"] == "refused"
    # a refusal is an outcome: run again, it is skipped; with retry_failed it runs
    again = Events()
    sw.sweep(THREE_MASS, variants=["f1", "f100"], grid=grid, out=tmp_path, progress=again)
    assert not again.ran
    retry = Events()
    sw.sweep(THREE_MASS, variants=["f1", "f100"], grid=grid, out=tmp_path, progress=retry,
             retry_failed=True)
    assert retry.ran == [refused["point"]]

    rows = sw.sweep(THREE_MASS, variants=["f100"], scheme="implicit",
                    grid={**NEAR, "t_end": [0.03, -1.0], "scheme.max_iterations": [2, 50]})
    got = [(r["set.t_end"], r["set.scheme.max_iterations"], r["status"]) for r in rows]
    assert got == [(0.03, 2, "failed"), (0.03, 50, "finished"), (-1.0, 2, "refused"),
                   (-1.0, 50, "refused")]
    assert "did not converge" in rows[0]["message"]
    assert "`t_end` must be > 0 s" in rows[2]["message"]


# ---------------------------------------------------------- command line
def test_cli_sweep_writes_table_and_plot(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = tmp_path / "s"
    code = cli.main(["sweep", str(THREE_MASS), "--variants", "f1,f100",
                     "--set", "subsystems.robot.bodies.arm.joint.q0=0.45",
                     "--set", "t_end=0.03,0.04", "--workers", "2", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "4 of 4 point(s) finished" in text and "sweep.png" in text
    rows = sw.read_table(out / sw.TABLE)
    assert [(r["variant"], r["set.t_end"]) for r in rows] == [
        ("f1", 0.03), ("f1", 0.04), ("f100", 0.03), ("f100", 0.04)]
    assert (out / sw.PLOT).read_bytes()[:4] == b"\x89PNG"
    # again: nothing runs, the same table
    assert cli.main(["sweep", str(THREE_MASS), "--variants", "f1,f100",
                     "--set", "subsystems.robot.bodies.arm.joint.q0=0.45",
                     "--set", "t_end=0.03,0.04", "--out", str(out), "--no-plot"]) == 0
    assert "4 done before" in capsys.readouterr().out
    assert json.dumps(sw.read_table(out / sw.TABLE)) == json.dumps(rows)   # NaN too


def test_cli_sweep_exit_status(tmp_path, capsys):
    args = ["sweep", str(THREE_MASS), "--variants", "f100", "--no-plot", "--workers", "1",
            "--out", str(tmp_path)]
    assert cli.main(args + ["--set", "t_end=-1"]) == 1          # the table says why
    assert "must be > 0 s" in capsys.readouterr().out
    assert cli.main(args + ["--set", "t_end=1", "--set", "t_end=2"]) == 2
    assert "given twice" in capsys.readouterr().err
    assert cli.main(["sweep", "--study", "fig8_stiffness", str(THREE_MASS)]) == 2
    assert cli.main(["sweep"]) == 2


def test_a_sweep_loads_neither_dask_nor_matplotlib():
    """Only --scheduler loads Dask, only the plot matplotlib (DESIGN.md)."""
    code = (
        "import sys, cosim.cli\n"
        "from cosim.studies import sweep\n"
        f"rows = sweep.sweep({str(THREE_MASS)!r}, variants=['f1'], grid={{'t_end': [0.01]}},"
        " workers=2)\n"
        "assert rows[0]['status'] == 'finished', rows\n"
        "print(sorted(m for m in ('dask', 'distributed', 'matplotlib', 'tqdm')"
        " if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_a_scene_warning_shows_once_per_sweep_not_once_per_point():
    """An option the scene's own scheme ignores (here given by the grid) is
    the scene's to fix: it warns, once for the whole sweep."""
    with pytest.warns(UserWarning, match="ignores the options") as caught:
        rows = sw.sweep(SPRING_DROP, grid={"t_end": [0.001, 0.002],
                                           "scheme.max_iterations": [3]})
    assert [r["status"] for r in rows] == ["finished", "finished"]
    assert len([w for w in caught if "ignores the options" in str(w.message)]) == 1
