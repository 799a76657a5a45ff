"""Read a run folder with numpy alone and plot it.

A run folder holds ``summary.json`` (counts, contact intervals, energy) and ``series.npz``
(every quantity at the same sample times: ``t``, ``force/C``, ``q/chain/m1``,
``energy/total``, ...). This script makes one, as ``cosim run`` does::

    cosim run cases/three_mass.toml --variant f100 --set t_end=0.25 --out runs/examples/read_run/run

(here through ``cosim.run_scene(..., out=...)``), then reads it back with ``json`` and
``numpy.load`` only, so the reading part works wherever numpy does, without cosim. Give
``--run DIR`` to read a folder you made yourself (any scene with a contact ``C``).

The figure ``docs/_static/examples/read_run.png`` was made by::

    python examples/read_run.py
"""
import argparse
import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

SCENE = Path(__file__).resolve().parents[1] / "cases" / "three_mass.toml"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=0.25,
                        help="end time [s] (C strikes at 0.103 s)")
    parser.add_argument("--out", type=Path, default=Path("runs/examples/read_run"))
    parser.add_argument("--run", type=Path, help="read this run folder instead of making one")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    run = args.run
    if run is None:
        import cosim
        run = args.out / "run"
        cosim.run_scene(SCENE, variant="f100", overrides=[f"t_end={args.t_end}"], out=run,
                        overwrite=True, estimate=False)

    # -- from here on: json and numpy only
    summary = json.loads((run / "summary.json").read_text())
    with np.load(run / "series.npz") as npz:
        series = {name: npz[name] for name in npz.files}
    t, force = series["t"], series["force/C"]
    intervals = summary["contacts"]["C"]["intervals"]
    closed = np.zeros(t.shape, bool)       # samples inside one of the summary's intervals
    for t_on, t_off in intervals:
        closed |= (t >= t_on) & (t <= t_off)
    print(f"{summary['scene']} under {summary['scheme']}: {len(t)} samples, "
          f"{summary['contacts']['C']['count']} contacts of C, "
          f"energy drift {summary['energy']['max_abs_drift']:.3g} J")
    outside = int(np.count_nonzero((force > 0) & ~closed))
    print(f"samples with force on C outside its intervals: {outside}")
    (args.out / "read_run.json").write_text(json.dumps(
        {"samples": len(t), "forced_outside": outside,
         "forced_inside": int(np.count_nonzero((force > 0) & closed)),
         "energy_initial": summary["energy"]["initial"],
         "energy_first_sample": float(series["energy/total"][0])}, indent=1))

    fig = Figure(figsize=(8, 5), dpi=100, layout="constrained")
    ax_f, ax_q, ax_e = fig.subplots(3, 1, sharex=True)
    ax_f.plot(t * 1e3, force, color="C3", lw=0.9)
    ax_f.set_ylabel("force/C [N]")
    for name in sorted(n for n in series if n.startswith("q/chain/")):
        ax_q.plot(t * 1e3, series[name] * 1e3, lw=0.9, label=name)
    ax_q.set_ylabel("chain [mm]")
    ax_q.legend(loc="lower left", ncols=3, fontsize="small")
    ax_e.plot(t * 1e3, series["energy/total"], color="k", lw=0.9, label="energy/total")
    ax_e.set_ylabel("energy [J]")
    ax_e.set_xlabel("time [ms]")
    for t_on, t_off in intervals:
        for ax in (ax_f, ax_q, ax_e):
            ax.axvspan(t_on * 1e3, t_off * 1e3, color="C3", alpha=0.15, lw=0)
    if intervals:
        ax_f.set_xlim(1e3 * intervals[0][0] - 5.0, 1e3 * min(t[-1], intervals[-1][1] + 0.03))
    fig.savefig(args.out / "read_run.png")
    print(f"wrote {args.out / 'read_run.png'}")


if __name__ == "__main__":
    main()
