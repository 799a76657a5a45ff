"""Where two pages, or a page and the code, could say different things:
each claim run against the code, and the pages that repeat it held to one
wording.

- the chatter example's stop (docs/troubleshooting.md, twice): the time the
  guard names when `cosim run examples/chatter.toml` stops;
- the friction paragraph's RK4 limit (docs/contacts.md): the sliding block
  settles with RK4 steps just below it and keeps creeping just above;
- `scheme.accuracy` (docs/accuracy.md, docs/commands.md): `cosim run` reads
  it;
- the animation's format (`cosim plot --help`, docs/getting-started.md): MP4
  where matplotlib finds ffmpeg, else GIF, as the code chooses;
- the timings the guides quote (docs/structures.md, docs/contacts.md): the
  published run of docs/performance.md's scenes table.
"""
from __future__ import annotations

import json
import re
import sys
import warnings

import numpy as np
import pytest

from documented import ROOT, Claim, assert_printed, assert_reproduced, flat

from cosim.cli import main

TS, C, A, G, S = ("docs/troubleshooting.md", "docs/contacts.md", "docs/accuracy.md",
                  "docs/getting-started.md", "docs/structures.md")


def test_the_chatter_example_stops_where_the_page_says(tmp_path, capsys):
    """`cosim run examples/chatter.toml` stops on chatter at t = 0.428353 s
    (the guard's own time, in its message), as both places of the page say."""
    assert main(["run", str(ROOT / "examples" / "chatter.toml"), "--out", str(tmp_path / "r"),
                 "--quiet", "--no-estimate"]) == 1
    message = json.loads((tmp_path / "r" / "summary.json").read_text())["message"]
    assert "chatters" in message, message
    at = float(re.search(r"the guard tripped at t = ([\d.]+) s", message).group(1))
    for printed in ("(for example `cosim run examples/chatter.toml`, which stops at "
                    "t = 0.428353 s)", "its impacts accumulate at t = 0.428353 s, and the guard "
                                       "stops it there"):
        claim = Claim(TS, printed, "cosim run examples/chatter.toml", 0.428353, abs=0.5e-6)
        assert_printed(claim)
        assert_reproduced(claim, at)


def _slide(tmp_path, max_step: float) -> float:
    """The sliding block of tests/test_connections.py with its friction
    embedded (RK4 integrates it): the largest speed left after it stops."""
    import cosim
    from cosim.scene.load import load_scene
    sys.path.insert(0, str(ROOT / "tests"))
    from test_connections import MASS, SLIDE, scene_text
    fr = "friction = { coefficient = 0.3, slip_velocity = 0.0001 }"
    path = tmp_path / f"slide-{max_step:g}.toml"
    path.write_text(scene_text(SLIDE.format(k=1e6, friction=fr), t_end=0.4, dq0=(1.0, 0.0),
                               q0=(0.0, -MASS * 9.81 / 1e6), max_step=max_step))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cosim.simulate(load_scene(path, overrides=["scheme.macro_step=1e-3"],
                                        scheme="gauss_seidel"), estimate=False)
    assert res.status == "finished", res.message
    after = res.t > 1.0 / (0.3 * 9.81) + 0.01          # past the stop at v0 / (mu g)
    return float(np.max(np.abs(res.series["dq/robot/x"][after])))


def test_the_friction_damper_needs_rk4_steps_below_the_limit_the_page_names(tmp_path):
    """"the sliding test (2 kg, μ = 0.3, v_s = 1e-4 m/s) needs RK4 steps below
    9.5e-5 s": with the macro step of 1 ms cut into 11 RK4 steps (9.09e-5 s,
    4 % below) the block comes to rest; into 10 (1e-4 s, 6 % above) it keeps
    creeping at a sixth of v_s, the damper's RK4 step past its stability
    limit (h μ g / v_s = 2.785)."""
    claim = Claim(C, "needs RK4 steps below 9.5e-5 s", "the sliding block, gauss_seidel",
                  9.5e-5, abs=0.05e-5)
    assert_printed(claim)
    below, above = _slide(tmp_path, 9.1e-5), _slide(tmp_path, 1e-4)
    assert below < 1e-9 and above > 1e-6, (below, above)
    assert 1e-3 / 11 < claim.value < 1e-4                 # the limit lies between them


def test_a_run_reads_the_scenes_accuracy(tmp_path, capsys):
    """`accuracy = "1%"` in a scene's `[scheme]`: `cosim run` asks it when the
    flag is not given (docs/accuracy.md says so, docs/commands.md too)."""
    assert_printed(Claim(A, "`accuracy = \"1%\"` in a scene's `[scheme]` asks the same when the "
                            "flag is not given (`cosim run` and `cosim info` both read it)", "", 0))
    assert_printed(Claim("docs/commands.md", "`--accuracy X` (`1%`, `0.01`; without it the "
                                             "scene's `scheme.accuracy`, if any) runs", "", 0))
    out = tmp_path / "r"
    assert main(["run", str(ROOT / "cases" / "spring_drop.toml"), "--variant", "undamped",
                 "--set", 'scheme.accuracy="1%"', "--out", str(out), "--quiet"]) == 0
    request = json.loads((out / "summary.json").read_text())["accuracy"]["request"]
    assert request["from"] == "scheme.accuracy" and request["accuracy"] == 0.01, request
    assert "accuracy asked 1 % (scheme.accuracy)" in capsys.readouterr().out


def test_the_animation_format_is_said_once_as_the_code_chooses(monkeypatch, capsys):
    """MP4 where matplotlib finds ffmpeg, else GIF: the code's choice, the
    help text and the page say the same."""
    pytest.importorskip("matplotlib")
    from matplotlib import animation as mpl_animation
    from cosim.plot import animation
    for found, suffix in ((True, "mp4"), (False, "gif")):
        monkeypatch.setattr(mpl_animation.writers, "is_available", lambda name, f=found: f)
        assert animation._encoder(None)[1] == suffix
    with pytest.raises(SystemExit):
        main(["plot", "--help"])
    assert "(MP4 with ffmpeg where matplotlib finds it, else GIF with Pillow)" in \
        flat(capsys.readouterr().out)
    for printed in ("# + animation.mp4 (ffmpeg), else .gif (Pillow)",
                    "It writes `animation.mp4` (H.264) where matplotlib finds ffmpeg, else "
                    "`animation.gif` (Pillow"):
        assert_printed(Claim(G, printed, "cosim plot --animate", 0))
    assert "GIF with Pillow, else MP4" not in flat((ROOT / G).read_text(encoding="utf-8"))


def _scene_cpu(scene: str, scheme: str) -> float:
    """Solve CPU of ``scene`` under ``scheme`` (no overrides) in the published
    run of docs/performance.md's scenes table."""
    data = json.loads((ROOT / "benchmarks" / "results" / "scenes" / "scenes.json").read_text())
    (row,) = [r for r in data["rows"]
              if r["scene"] == scene and r["scheme"] == scheme and not r["overrides"]]
    assert data["date"] == "2026-12-02"
    return row["cpu_s"]["compiled"]


@pytest.mark.parametrize("page, printed, scene, scheme, value", [
    (S, "the reference's solve takes 0.758 s of CPU and the scene's default 0.014 s",
     "beam_impact", "monolithic", 0.758),
    (S, "the reference's solve takes 0.758 s of CPU and the scene's default 0.014 s",
     "beam_impact", "gauss_seidel", 0.014),
    (C, "the default run's solve takes 0.024 s of CPU, the monolithic reference's 8.126 s",
     "brachiation", "implicit", 0.024),
    (C, "the default run's solve takes 0.024 s of CPU, the monolithic reference's 8.126 s",
     "brachiation", "monolithic", 8.126),
])
def test_the_guides_timings_are_the_published_runs(page, printed, scene, scheme, value):
    """A guide quotes a timing from the one published run of the scenes table,
    which docs/performance.md shows whole: the same number on both pages."""
    claim = Claim(page, printed, "python benchmarks/scenes.py --kernels compiled --repeat 3",
                  value, abs=0.0005)
    assert_printed(claim)
    assert_printed(Claim(page, "(*Compiled kernels and loops*: 2026-12-02, a shared", "", 0))
    assert_reproduced(claim, _scene_cpu(scene, scheme))
    # the table prints the run's value to 4 decimals, the guide to 3
    table = (ROOT / "docs" / "performance.md").read_text(encoding="utf-8")
    assert f"| {_scene_cpu(scene, scheme):.4f} |" in table


def _sweep_cost(key: str) -> float:
    data = json.loads((ROOT / "benchmarks" / "results" / "sweep_costs" / "sweep_costs.json")
                      .read_text())
    assert data["date"] == "2026-12-02" and data["finished"] == data["points"] == 8
    assert data["tables_identical"] and data["tables_compared"] == 3
    return data["cpu_s"][key] if key in data["cpu_s"] else data[key]


_SW = "docs/sweeps.md"
_SWEEP = ("1.20 s on one process and 2.00 s with `--workers 2`, of which the runs themselves "
          "account for 0.74 s (`cpu_time_s`): each of the pool's processes starts and imports "
          "cosim (0.26 s of CPU). `--scheduler local` takes 4.63 s, the extra being the "
          "cluster's start. Run again, the sweep reads the 8 points back in 0.41 s. The three "
          "tables (one process, pool, Dask) are identical apart from `cpu_time_s`.")


@pytest.mark.parametrize("key, value", [("one_process", 1.20), ("pool_2", 2.00), ("runs", 0.74),
                                        ("import", 0.26), ("dask_local", 4.63),
                                        ("read_back", 0.41), ("load_average", 5.4)])
def test_the_sweep_costs_are_the_published_runs(key, value):
    """docs/sweeps.md's paragraph of costs: one run of
    `python benchmarks/sweep_costs.py`, its file, half a unit of each digit."""
    claim = Claim(_SW, _SWEEP if key != "load_average" else
                  "(2026-12-02, a shared 2-core x86_64 machine at load average 5.4;",
                  "python benchmarks/sweep_costs.py", value, abs=0.005 if key != "load_average"
                  else 0.05)
    assert_printed(claim)
    assert_reproduced(claim, _sweep_cost(key))
    assert_printed(Claim(_SW, "each imports cosim once (0.26 s of CPU in the run quoted", "", 0))


def test_what_the_estimate_costs_is_said_as_a_run_counts_it(capsys):
    """`cosim run --help` on `--no-estimate` and docs/commands.md give the two
    companions' factors and their share of the run's macro steps; spring_drop,
    whose free flight and contact are both stepped at the scheme's steps,
    counts it (``work_share.macro_steps``: sqrt(2) + 1/sqrt(2) = 2.12 where
    every step scales)."""
    from cosim import load_scene, simulate
    from cosim.studies.estimate import estimate_errors
    scene = load_scene(ROOT / "cases" / "spring_drop.toml")
    acc = estimate_errors(scene, simulate(scene))
    share = acc["work_share"]["macro_steps"]
    assert f"{share:.1f}" == "2.1", share
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = flat(capsys.readouterr().out)
    assert ("skip the error estimate (two companion runs, at 0.71 and 1.41 times the step, "
            "together about 2.1 times the run's macro steps; none where nothing could be "
            "read; summary key `accuracy`)") in text, text
    page = flat((ROOT / "docs" / "commands.md").read_text())
    assert "two cost about 2.1 times the run's steps (`work_share`)" in page
    assert [f"{f:.2f}" for f in (acc["factor"] ** -1, acc["factor"])] == ["0.71", "1.41"]


def _published(folder: str, name: str) -> dict:
    data = json.loads((ROOT / "benchmarks" / "results" / folder / name).read_text())
    assert data["date"] == "2026-12-02"
    return data


_BUILD = ("the compilation took 90 s of CPU and 0.9 min of wall time")


def test_the_readme_build_is_the_published_run():
    """The README's install paragraph: seventeen compiled modules (the sources'
    .pyx files, each built), and the CPU and wall time of the one published
    build."""
    data = _published("compile", "build.json")
    pyx = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "src").rglob("*.pyx"))
    assert data["pyx"] == pyx and len(data["built"]) == len(pyx)
    modules = Claim("README.md", "first compiles cosim's seventeen compiled modules",
                    "ls src/**/*.pyx", 17)
    assert_printed(modules)
    assert_reproduced(modules, len(pyx))
    for value, measured, tol in ((90, data["cpu_s"], 0.5), (0.9, data["wall_s"] / 60, 0.05)):
        claim = Claim("README.md", _BUILD, "python benchmarks/build_time.py", value, abs=tol)
        assert_printed(claim)
        assert_reproduced(claim, measured)


_PLOT = ("`cosim plot` of spring_drop takes 1.78 s of CPU for its four PNGs, matplotlib's "
         "import included, and `cosim plot runs/three_mass-f100 --animate` 4.80 s for its five "
         "PNGs and the 200-frame GIF, of which the animation takes 2.01 s (10 ms a frame; "
         "drawing each frame whole, as matplotlib's stock writer does, took 27.6 s).")


def test_what_plotting_costs_is_the_published_run():
    data = _published("animation", "animation.json")
    assert data["frames"] == 200 and data["video"] == "gif"
    assert data["pngs"] == {"spring_drop": 4, "three_mass": 5}
    for value, measured, tol in ((1.78, data["plot_spring_drop_cpu_s"], 0.005),
                                 (4.80, data["plot_animate_three_mass_cpu_s"], 0.005),
                                 (2.01, data["cosim_s"]["cpu"], 0.005),
                                 (10, 1e3 * data["cosim_s"]["cpu"] / data["frames"], 0.5),
                                 (27.6, data["stock_s"]["cpu"], 0.05)):
        claim = Claim(G, _PLOT, "python benchmarks/animation.py --repeat 2", value, abs=tol)
        assert_printed(claim)
        assert_reproduced(claim, measured)


def test_the_plug_in_strings_lowest_frequency_is_the_strings_shifted():
    """docs/plugins.md: "The lowest frequency, 57.5 Hz, is the 40-element
    string's 8.925 Hz shifted by the foundation's sqrt(k_f / (rho A)) / (2 pi)
    = 56.8 Hz": cosim's own string of the example scene's numbers, and the
    shift that the plug-in adds to its stiffness."""
    import math
    import fem
    page = "docs/plugins.md"
    text = ("The lowest frequency, 57.5 Hz, is the 40-element string's 8.925 Hz shifted by "
            "the foundation's sqrt(k_f / (rho A)) / (2 pi) = 56.8 Hz.")
    string = fem.String(length=2.0, tension=1000.0, density=7850.0, area=1e-4,
                        n_elements=40).assemble()
    f0 = float(fem.natural_frequencies(string, 1)[0])
    fk = math.sqrt(1e5 / (7850.0 * 1e-4)) / (2 * math.pi)
    scene = (ROOT / "examples" / "custom_structure" / "scene.toml").read_text()
    for key, value in (("length", "2.0"), ("tension", "1000.0"), ("density", "7850.0"),
                       ("area", "1e-4"), ("foundation_stiffness", "1e5"), ("elements", "40")):
        assert re.search(rf"^{key} = {re.escape(value)}\b", scene, flags=re.M), key
    for value, measured, tol in ((8.925, f0, 0.0005), (56.8, fk, 0.05),
                                 (57.5, math.hypot(f0, fk), 0.05)):
        claim = Claim(page, text, "cosim info examples/custom_structure/scene.toml", value,
                      abs=tol)
        assert_printed(claim)
        assert_reproduced(claim, measured)
