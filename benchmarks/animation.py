"""What `cosim plot --animate` costs: the animation of three_mass f100 (the
README's scene), 200 frames, drawn as :func:`cosim.plot.animate_run` draws
them and as matplotlib's stock writers do.

Run from the project root: ``python benchmarks/animation.py [--frames 200]
[--repeat 3]``.  The run is made once, into a temporary folder; then, in this
process, each way is timed ``--repeat`` times (wall, ``time.perf_counter``,
and CPU, ``time.process_time``, which a loaded machine inflates far less),
and the best of each is printed:

- *cosim*: :func:`cosim.plot.animate_run` as `cosim plot --animate` calls
  it: the figure laid out and its still parts drawn once, each frame only the
  moving artists drawn over them, the pixels handed to Pillow (GIF) or
  ffmpeg (MP4);
- *stock*: the same figure and poses through ``matplotlib.animation``'s
  ``PillowWriter`` (``grab_frame``), which lays out and draws the whole
  figure for every frame (``savefig``): what `cosim plot --animate` did
  before.

Both write a GIF (Pillow) so that the encoders compare too; ``--video mp4``
times cosim's MP4 instead, where ffmpeg is installed.

Beside them it reads the CPU (user + sys, ``os.wait4``) of two whole
commands in fresh processes, matplotlib's import included: ``cosim plot`` of
a spring_drop run and ``cosim plot --animate`` of the three_mass f100 run.
``--out DIR`` writes all of it as ``DIR/animation.json`` through cosim's
checked writer (the published run is in ``benchmarks/results/animation``).
"""
import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _stock(run, path, frames, fps):
    """The figure and poses of :mod:`cosim.plot.animation`, written by
    matplotlib's PillowWriter, each frame laid out and drawn whole."""
    from matplotlib import animation as mpl_animation
    from matplotlib import rc_context

    from cosim.plot import animation
    from cosim.plot.scene_geometry import scene_geometry

    geo = scene_geometry(run.scene, run.path / "scene.toml")
    idx = animation._frames(len(run.t), frames)
    with rc_context({"text.parse_math": False}):
        fig, draw, _, _ = animation._figure(run, geo, idx, 1.0)
        writer = mpl_animation.PillowWriter(fps=fps)
        with writer.saving(fig, str(path), dpi=animation._DPI):
            for k, i in enumerate(idx):
                draw(k, i)
                writer.grab_frame()


def _command_cpu(argv) -> float:
    """CPU [s] (user + sys) of ``argv`` run in a fresh process."""
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(map(str, argv))} failed")
    return usage.ru_utime + usage.ru_stime


def _best(fn, repeat):
    best = [float("inf"), float("inf")]
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        fn()
        best = [min(best[0], time.perf_counter() - w), min(best[1], time.process_time() - c)]
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=200, help="frames (default 200)")
    ap.add_argument("--repeat", type=int, default=3, help="timings of each way (default 3)")
    ap.add_argument("--video", choices=("gif", "mp4"), default="gif",
                    help="cosim's encoder (default gif, as the stock writer)")
    ap.add_argument("--out", default=None, help="write DIR/animation.json")
    args = ap.parse_args(argv)

    from cosim.plot import animate_run, load_run

    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp) / "three_mass-f100"
        subprocess.run([sys.executable, "-m", "cosim.cli", "run",
                        str(ROOT / "cases" / "three_mass.toml"), "--variant", "f100",
                        "--out", str(run_dir), "--quiet"], check=True, stdout=subprocess.DEVNULL)
        run = load_run(run_dir)
        ours = _best(lambda: animate_run(run, Path(tmp) / "cosim", max_frames=args.frames,
                                         video=args.video), args.repeat)
        stock = _best(lambda: _stock(run, Path(tmp) / "stock.gif", args.frames, 20), args.repeat)
        size = {p.name: p.stat().st_size for p in (Path(tmp) / "cosim").glob("animation.*")}
        size["stock.gif"] = (Path(tmp) / "stock.gif").stat().st_size
        cli = [sys.executable, "-m", "cosim.cli"]
        drop = Path(tmp) / "spring_drop"
        subprocess.run(cli + ["run", str(ROOT / "cases" / "spring_drop.toml"), "--out",
                              str(drop), "--quiet"], check=True, stdout=subprocess.DEVNULL)
        plot_cpu = min(_command_cpu(cli + ["plot", str(drop), "--out", str(Path(tmp) / f"p{k}")])
                       for k in range(args.repeat))
        animate_cpu = min(_command_cpu(cli + ["plot", str(run_dir), "--animate", "--quiet",
                                              "--out", str(Path(tmp) / f"a{k}")])
                          for k in range(args.repeat))
        pngs = {"spring_drop": len(list((Path(tmp) / "p0").glob("*.png"))),
                "three_mass": len(list((Path(tmp) / "a0").glob("*.png")))}
    print(f"three_mass f100, {args.frames} frames, best of {args.repeat}; "
          f"python {platform.python_version()}, {platform.machine()}")
    print(f"{'':8} {'wall [s]':>9} {'cpu [s]':>9}")
    print(f"{'cosim':8} {ours[0]:9.2f} {ours[1]:9.2f}")
    print(f"{'stock':8} {stock[0]:9.2f} {stock[1]:9.2f}")
    print(f"stock / cosim: wall x{stock[0] / ours[0]:.1f}, cpu x{stock[1] / ours[1]:.1f}")
    print("files: " + ", ".join(f"{k} {v / 1024:.0f} KiB" for k, v in sorted(size.items())))
    print(f"cosim plot of spring_drop: {plot_cpu:.2f} s CPU ({pngs['spring_drop']} PNGs); "
          f"cosim plot --animate of three_mass f100: {animate_cpu:.2f} s CPU "
          f"({pngs['three_mass']} PNGs and the animation)")
    if args.out:
        from cosim.io.rundir import OutputFolder
        data = {"machine": f"{platform.machine()}, {os.cpu_count()} cores, Python "
                           f"{platform.python_version()}",
                "date": datetime.date.today().isoformat(), "load_average": os.getloadavg()[0],
                "frames": args.frames, "repeat": args.repeat, "video": args.video,
                "cosim_s": {"wall": ours[0], "cpu": ours[1]},
                "stock_s": {"wall": stock[0], "cpu": stock[1]}, "bytes": size,
                "plot_spring_drop_cpu_s": plot_cpu, "plot_animate_three_mass_cpu_s": animate_cpu,
                "pngs": pngs}
        with OutputFolder(args.out) as folder:
            folder.write("animation.json", lambda fh: json.dump(data, fh, indent=1), "w")
        print(f"wrote {args.out}/animation.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
