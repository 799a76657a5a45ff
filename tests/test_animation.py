"""`cosim plot --animate`: frames drawn once over a still background, a GIF
through Pillow or an MP4 through ffmpeg, a progress bar on a terminal, and
titles that stay inside the figure.  (Its speed is measured by
benchmarks/animation.py, not here.)"""
import json
import os
import shutil
import stat
import sys

import numpy as np
import pytest

from conftest import CASES
from cosim import cli
from cosim.cli import terminal

pytest.importorskip("matplotlib")
Image = pytest.importorskip("PIL.Image")

#: the frames' size [pixels]: 6.4 x 4.8 inches at 80 dpi
WIDTH, HEIGHT = 512, 384
#: a reason long enough to run off both edges of a figure on one line
LONG = ("the run guard stopped the run: the energy grew by 13.42 J over the last "
        "window, beyond the bound of 4.51 J that the contacts' stored energy and the "
        "drives' work allow; reduce the macro step or pick the implicit scheme")


@pytest.fixture(scope="module")
def arm_run(tmp_path_factory):
    """three_mass f100 cut short (31 samples): a robot that moves, a chain,
    three contacts."""
    out = tmp_path_factory.mktemp("runs") / "three_mass"
    assert cli.main(["run", str(CASES / "three_mass.toml"), "--variant", "f100",
                     "--set", "t_end=0.06", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.fixture()
def no_ffmpeg(monkeypatch):
    """matplotlib finds no ffmpeg (whether or not this machine has one)."""
    from matplotlib import rcParams
    monkeypatch.setitem(rcParams, "animation.ffmpeg_path", "no-such-ffmpeg-here")


def _incomplete(run, dest):
    """A copy of ``run`` whose summary says it failed, with a long message."""
    shutil.copytree(run, dest)
    s = json.loads((dest / "summary.json").read_text())
    s["status"], s["message"] = "failed", LONG
    (dest / "summary.json").write_text(json.dumps(s))
    return dest


def test_gif_has_every_frame_at_its_size(arm_run, tmp_path, no_ffmpeg):
    from cosim.plot import animate_run

    done = []
    path = animate_run(arm_run, tmp_path, max_frames=12, fps=25,
                       progress=lambda k, n: done.append((k, n)))
    assert path == tmp_path / "animation.gif"
    assert done == [(k, 12) for k in range(1, 13)]                 # once per frame, in order
    with Image.open(path) as im:
        assert im.n_frames == 12 and im.size == (WIDTH, HEIGHT)
        assert im.info["duration"] == 40 and im.info["loop"] == 0  # 25 frames per second
        frames = []
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB")))
    # the robot moves: no two frames alike, and a file of 12 distinct frames
    assert all(np.any(a != b) for a, b in zip(frames, frames[1:]))
    assert 20_000 < path.stat().st_size < 12 * WIDTH * HEIGHT


def test_a_frame_is_the_figure_drawn_whole(arm_run):
    """Drawing only the moving artists over the background gives the picture
    a full draw gives: pixels differ only where a moving artist and a still
    one overlap (drawn in another order), a small fraction of them."""
    from cosim import plot
    from cosim.plot import animation
    from cosim.plot.scene_geometry import scene_geometry

    run = plot.load_run(arm_run)
    geo = scene_geometry(run.scene, arm_run / "scene.toml")
    idx = animation._frames(len(run.t), 5)
    fig, draw, moving, legend = animation._figure(run, geo, idx, 1.0)
    frames = animation._Frames(fig, draw, moving, legend, idx)
    for k in (1, 4):
        blitted = frames[k][..., :3].astype(int)
        for a in moving:
            a.set_animated(False)
        fig.canvas.draw()                                          # the whole figure
        whole = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
        for a in moving:
            a.set_animated(True)
        changed = np.any(np.abs(blitted - whole) > 8, axis=-1).mean()
        assert changed < 0.002, (k, changed)
    # and a frame is not the background alone: the robot is drawn over it
    background = np.asarray(frames._background)[..., :3].astype(int)
    assert np.any(np.abs(frames[2][..., :3].astype(int) - background) > 8, axis=-1).mean() > 0.002


def test_title_of_an_incomplete_run_stays_inside(arm_run, tmp_path):
    from cosim import plot
    from cosim.plot import animation, figures
    from cosim.plot.scene_geometry import scene_geometry

    part = _incomplete(arm_run, tmp_path / "part")
    run = plot.load_run(part)
    assert "INCOMPLETE run: status 'failed' (the run guard" in run.title()
    geo = scene_geometry(run.scene, part / "scene.toml")
    idx = animation._frames(len(run.t), 3)
    fig, draw, moving, legend = animation._figure(run, geo, idx, 1.0)
    frames = animation._Frames(fig, draw, moving, legend, idx)
    frames[2]
    renderer = fig.canvas.get_renderer()
    title = fig.axes[0].title
    box, page = title.get_window_extent(renderer), fig.bbox
    assert "INCOMPLETE run:" in title.get_text() and title.get_text().count("\n") >= 2
    assert page.x0 <= box.x0 and box.x1 <= page.x1 and box.y1 <= page.y1, (box, page)
    # unwrapped, the same text would not have fitted: the test can fail
    one_line = title.get_text().replace("\n", " ")
    width = renderer.get_text_width_height_descent(one_line, title.get_fontproperties(),
                                                   ismath=False)[0]
    assert width > page.width
    # the time-history figures' titles, too
    fig = figures._force_figure(run)
    fig.canvas.draw()
    box, page = fig._suptitle.get_window_extent(fig.canvas.get_renderer()), fig.bbox
    assert "INCOMPLETE" in fig._suptitle.get_text()
    assert page.x0 <= box.x0 and box.x1 <= page.x1 and box.y1 <= page.y1, (box, page)


def test_wrapped_breaks_at_spaces_and_inside_long_words():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from cosim.plot.figures import wrapped

    fig = Figure(figsize=(3, 2), dpi=100)
    FigureCanvasAgg(fig)
    text = "short\n" + " ".join(["word"] * 40) + " " + "x" * 200
    out = wrapped(fig, text, 9, 200.0)
    assert out.replace("\n", "").replace(" ", "") == text.replace("\n", "").replace(" ", "")
    lines = out.split("\n")
    assert lines[0] == "short" and len(lines) > 6
    assert all(not ln.startswith(" ") and not ln.endswith(" ") for ln in lines)
    from matplotlib.font_manager import FontProperties
    r, font = fig.canvas.get_renderer(), FontProperties(size=9)
    assert max(r.get_text_width_height_descent(ln, font, ismath=False)[0] for ln in lines) <= 200


def _fake_ffmpeg(folder, exit_code=0):
    """An executable standing for ffmpeg: it reads the frames piped to it and
    writes, as the output file, its arguments and the bytes it received."""
    exe = folder / "ffmpeg"
    exe.write_text(f"#!{sys.executable}\n"
                   "import json, sys\n"
                   "n = len(sys.stdin.buffer.read())\n"
                   f"if {exit_code}:\n"
                   "    sys.stderr.write('Unknown encoder h264')\n"
                   f"    sys.exit({exit_code})\n"
                   "open(sys.argv[-1], 'w').write(json.dumps({'args': sys.argv[1:], 'bytes': n}))\n")
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return exe


@pytest.mark.skipif(os.name != "posix", reason="the stand-in ffmpeg is a script with #!")
def test_mp4_where_ffmpeg_is_found_gets_raw_frames(arm_run, tmp_path, monkeypatch):
    from matplotlib import rcParams

    from cosim.plot import PlotError, animate_run

    monkeypatch.setitem(rcParams, "animation.ffmpeg_path", str(_fake_ffmpeg(tmp_path)))
    path = animate_run(arm_run, tmp_path / "v", max_frames=7, fps=10)
    assert path == tmp_path / "v" / "animation.mp4"
    got = json.loads(path.read_text())
    assert got["bytes"] == 7 * WIDTH * HEIGHT * 4                  # 7 RGBA frames, whole
    args = got["args"]
    assert args[args.index("-s") + 1] == f"{WIDTH}x{HEIGHT}" and args[args.index("-r") + 1] == "10"
    assert args[args.index("-pix_fmt") + 1] == "rgba"
    # a GIF still, when asked for
    assert animate_run(arm_run, tmp_path / "g", max_frames=3, video="gif").suffix == ".gif"
    # ffmpeg failing: its message, and no file left
    monkeypatch.setitem(rcParams, "animation.ffmpeg_path",
                        str(_fake_ffmpeg(tmp_path / "g", exit_code=1)))
    with pytest.raises(PlotError, match=r"failed \(exit 1\).*Unknown encoder h264"):
        animate_run(arm_run, tmp_path / "bad", max_frames=3)
    assert not any((tmp_path / "bad").iterdir())


def test_mp4_without_ffmpeg_is_refused(arm_run, tmp_path, no_ffmpeg):
    from cosim.plot import PlotError, animate_run

    with pytest.raises(PlotError, match="MP4 animation needs ffmpeg"):
        animate_run(arm_run, tmp_path, max_frames=3, video="mp4")
    with pytest.raises(ValueError, match="`video` must be"):
        animate_run(arm_run, tmp_path, video="avi")


def test_progress_bar_on_a_terminal_only(arm_run, tmp_path, monkeypatch, capsys, no_ffmpeg):
    pytest.importorskip("tqdm")
    argv = ["plot", str(arm_run), "--animate", "--frames", "9"]
    assert cli.main(argv + ["--out", str(tmp_path / "a")]) == 0
    assert capsys.readouterr().err == ""                           # not a terminal
    monkeypatch.setattr(terminal, "_on_terminal", lambda: True)
    assert cli.main(argv + ["--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    assert cli.main(argv + ["--out", str(tmp_path / "c")]) == 0
    captured = capsys.readouterr()
    assert "animation: 100%" in captured.err and "9/9" in captured.err
    assert f"wrote {tmp_path / 'c' / 'animation.gif'}" in captured.out


def test_progress_line_without_tqdm(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "tqdm", None)
    monkeypatch.setattr(terminal, "_on_terminal", lambda: True)
    bar = terminal._frame_progress(False)
    for k in range(1, 4):
        bar(k, 3)
    bar.close()
    assert capsys.readouterr().err == ("\ranimation: 1/3 frames\ranimation: 2/3 frames"
                                       "\ranimation: 3/3 frames\n")
    assert terminal._frame_progress(True) is None
