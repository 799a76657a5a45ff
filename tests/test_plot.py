"""Pictures and progress: `cosim plot` on finished and interrupted runs, the
animation, the progress hook, and `cosim run` staying free of matplotlib."""
import json
import re
import shutil
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from conftest import CASES, ROOT
from cosim import cli, load_scene, simulate
from cosim.cli import terminal

PNG = b"\x89PNG\r\n\x1a\n"
FIGURES = ("penetration", "force", "joint_velocity", "energy")


@pytest.fixture(scope="module")
def spring_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "spring_drop"
    assert cli.main(["run", str(CASES / "spring_drop.toml"), "--variant", "kelvin_voigt",
                     "--out", str(out), "--quiet"]) == 0
    return out


def _partial(run, dest, keep=0.4, status="failed"):
    """A copy of ``run`` cut to its first ``keep`` of samples, as if interrupted."""
    shutil.copytree(run, dest)
    with np.load(dest / "series.npz") as npz:
        series = {k: npz[k] for k in npz.files}
    n = int(keep * len(series["t"]))
    np.savez(dest / "series.npz", **{k: v[:n] for k, v in series.items()})
    s = json.loads((dest / "summary.json").read_text())
    s["status"], s["message"] = status, "interrupted"
    (dest / "summary.json").write_text(json.dumps(s))
    return dest


def test_run_writes_the_scene_it_ran(spring_run):
    """scene.toml is the merged scene: it loads on its own to the same table."""
    again = load_scene(spring_run / "scene.toml")
    ran = load_scene(CASES / "spring_drop.toml", "kelvin_voigt")
    assert again.data == {"name": "spring_drop", **ran.data}
    assert again.t_end == ran.t_end and again.name == "spring_drop"
    assert tomllib.loads((spring_run / "scene.toml").read_text())["contacts"]["wall"]["law"][
        "type"] == "kelvin_voigt"


def test_plot_writes_png_and_svg(spring_run, tmp_path, capsys):
    assert cli.main(["plot", str(spring_run), "--out", str(tmp_path / "png")]) == 0
    out = capsys.readouterr().out
    for name in FIGURES:
        f = tmp_path / "png" / f"{name}.png"
        assert f.read_bytes()[:8] == PNG and f.stat().st_size > 5000, name
        assert f"wrote {f}" in out
    assert not (tmp_path / "png" / "structure.png").exists()      # spring_drop has none
    assert "incomplete" not in out
    assert cli.main(["plot", str(spring_run), "--format", "svg", "--out",
                     str(tmp_path / "svg")]) == 0
    for name in FIGURES:
        text = (tmp_path / "svg" / f"{name}.svg").read_text()
        assert text.startswith("<?xml") and "<svg" in text


def test_figures_have_units_and_the_ledger(spring_run):
    from cosim import plot
    from cosim.plot import figures

    run = plot.load_run(spring_run)
    assert run.incomplete == "" and run.t_end == pytest.approx(0.02)
    for name, make in figures._FIGURES:
        fig = make(run)
        if fig is None:
            assert name == "structure"
            continue
        axes = fig.get_axes()
        assert axes[-1].get_xlabel() == "time [s]", name
        for ax in axes:
            assert re.search(r"\[(m|N|J|m/s|rad/s)\]", ax.get_ylabel()), (name, ax.get_ylabel())
    joints = figures._joint_velocity_figure(run).get_axes()
    assert joints[0].get_ylabel() == "velocity [m/s]"              # a prismatic joint
    energy = figures._energy_figure(run).get_axes()
    notes = " ".join(t.get_text() for ax in energy for t in ax.texts)
    assert "coupling error wall" in notes
    pen = figures._penetration_figure(run).get_axes()[0]
    assert len(pen.patches) == 1                                   # the one contact interval
    a, b = run.summary["contacts"]["wall"]["intervals"][0]
    x = pen.patches[0].get_path().transformed(pen.patches[0].get_patch_transform()).vertices[:, 0]
    assert x.min() == pytest.approx(a) and x.max() == pytest.approx(b)


def test_plot_draws_an_interrupted_run_and_says_so(spring_run, tmp_path, capsys):
    from cosim import plot
    from cosim.plot import figures

    part = _partial(spring_run, tmp_path / "part")
    assert cli.main(["plot", str(part)]) == 0
    out = capsys.readouterr().out
    assert "incomplete run: status 'failed' (interrupted)" in out
    assert "of 0.02 s" in out
    for name in FIGURES:
        assert (part / f"{name}.png").read_bytes()[:8] == PNG
    run = plot.load_run(part)
    assert "INCOMPLETE" in figures._force_figure(run)._suptitle.get_text()
    # no summary at all (killed before writing it): still drawn, still marked
    (part / "summary.json").unlink()
    assert cli.main(["plot", str(part), "--out", str(tmp_path / "nosum")]) == 0
    assert "no readable summary.json" in capsys.readouterr().out
    assert (tmp_path / "nosum" / "penetration.png").exists()
    # a status "finished" whose series stop early is incomplete too
    short = _partial(spring_run, tmp_path / "short", status="finished")
    assert "series reach t" in plot.load_run(short).incomplete


def test_plot_errors_exit_2(tmp_path, spring_run, capsys):
    assert cli.main(["plot", str(tmp_path / "nothing")]) == 2
    assert "series.npz: no such file" in capsys.readouterr().err
    old = tmp_path / "old"
    shutil.copytree(spring_run, old)
    (old / "scene.toml").unlink()
    assert cli.main(["plot", str(old), "--animate"]) == 2
    assert "scene.toml: no such file" in capsys.readouterr().err


def _writer_available():
    from matplotlib import animation
    return animation.writers.is_available("pillow") or animation.writers.is_available("ffmpeg")


def test_animation_has_frames(spring_run, tmp_path, capsys):
    if not _writer_available():
        pytest.skip("neither Pillow nor ffmpeg is installed")
    assert cli.main(["plot", str(spring_run), "--animate", "--frames", "12",
                     "--out", str(tmp_path)]) == 0
    gif = tmp_path / "animation.gif"
    if gif.exists():
        from PIL import Image
        with Image.open(gif) as im:
            assert im.n_frames == 12
    else:
        assert (tmp_path / "animation.mp4").stat().st_size > 0


def test_animation_poses_the_recorded_state(tmp_path):
    """The drawn robot and chain sit where the series put them."""
    from cosim import plot
    from cosim.plot import animation
    from cosim.plot.scene_geometry import scene_geometry

    out = tmp_path / "tm"
    assert cli.main(["run", str(CASES / "three_mass.toml"), "--variant", "f100",
                     "--set", "t_end=0.02", "--out", str(out), "--quiet"]) == 0
    run = plot.load_run(out)
    system = scene_geometry(run.scene, out / "scene.toml")
    idx = animation._frames(len(run.t), 7)
    assert idx[0] == 0 and idx[-1] == len(run.t) - 1 and len(idx) == 7
    robots, structures, fixed, contacts = animation._geometry(run, system, idx, 1.0)
    (_, lines, joints), = robots
    # the first two joints are sliders along x and y from the ground
    assert np.allclose([j[0].real for j in joints], run.series["q/robot/x"][idx])
    (_, ref, line, dotted), = structures
    chain = system.subsystems[system.names.index("chain")].structure
    u = np.column_stack([run.series[f"q/chain/{d}"][idx] for d in chain.dof_names])
    want = ref[None, :] + u * complex(*chain.direction)
    assert dotted and np.allclose(line, want)
    assert len(fixed) == 1 and len(contacts) == 3


def test_progress_hook_reports_increasing_time():
    scene = load_scene(CASES / "spring_drop.toml")
    calls = []
    res = simulate(scene, progress=calls.append, progress_interval=0.0)
    t = np.array([p.t for p in calls])
    assert len(calls) >= 100 and np.all(np.diff(t) > 0), t[:5]
    assert t[-1] == pytest.approx(scene.t_end)
    assert calls[0].contacts == 0 and calls[-1].contacts == res.summary["contacts"]["wall"][
        "count"] == 1
    assert all(p.t_end == scene.t_end for p in calls)
    # the default throttle: at most one call per 0.2 s of wall time, plus the first
    few = []
    simulate(scene, progress=few.append)
    assert 1 <= len(few) <= 1 + few[-1].elapsed_s / 0.2 + 1


def test_run_progress_line_only_on_a_terminal_and_not_quiet(monkeypatch, tmp_path, capsys):
    scene = str(CASES / "spring_drop.toml")
    monkeypatch.setattr(terminal, "PROGRESS_DELAY_S", 0.0)
    assert cli.main(["run", scene, "--out", str(tmp_path / "a")]) == 0
    assert capsys.readouterr().err == ""                           # not a terminal
    monkeypatch.setattr(terminal, "_on_terminal", lambda: True)
    assert cli.main(["run", scene, "--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    assert cli.main(["run", scene, "--out", str(tmp_path / "c")]) == 0
    err = capsys.readouterr().err
    assert "contacts" in err and "/0.02 s" in err and err.endswith("\r")


def test_run_does_not_import_matplotlib(tmp_path):
    code = ("import sys; from cosim import cli; "
            f"rc = cli.main(['run', {str(CASES / 'spring_drop.toml')!r}, '--out', "
            f"{str(tmp_path / 'o')!r}, '--quiet']); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('matplotlib', 'PIL', 'tqdm', 'skfem', 'meshio'))); sys.exit(rc)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[]"


def test_plot_without_matplotlib_names_the_extra(spring_run):
    code = ("import sys; sys.modules['matplotlib'] = None; from cosim import cli; "
            f"sys.exit(cli.main(['plot', {str(spring_run)!r}]))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip() == 'error: `cosim plot` needs matplotlib: pip install "cosim[plot]"'


@pytest.mark.parametrize("path", sorted(CASES.glob("*.toml")), ids=lambda p: p.stem)
def test_scene_toml_round_trips_every_variant(path):
    """What `cosim run` writes as scene.toml reads back to the table that ran."""
    from cosim.core.result import resolved_scene_text

    for variant in [None, *tomllib.loads(path.read_text()).get("variants", {})]:
        scene = load_scene(path, variant)
        back = tomllib.loads(resolved_scene_text(scene))
        assert back == {"name": scene.name, **scene.data}, variant


def test_toml_writer_quotes_and_refuses():
    from cosim.io.tomlwrite import dumps

    data = {"a.b": {"x y": [1, 2.5e-07, "q\"uote\n"], "inf": float("inf"), "t": True},
            "top": [{"k": 1}, {"k": 2}], "empty": {}}
    assert tomllib.loads(dumps(data)) == data
    with pytest.raises(TypeError, match="cannot write"):
        dumps({"when": object()})
