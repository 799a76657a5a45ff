"""The work-precision figure of ``cosim bench``: errors against CPU time,
one line per scheme, with the band over the round-off copies.  Needs
matplotlib (``pip install "cosim[plot]"``)."""
from __future__ import annotations

import math
from pathlib import Path

from cosim.io.rundir import OutputFolder
from cosim.studies.bench import BenchRow, _write

__all__ = ["plot"]


def plot(rows, path, title="", folder: OutputFolder | None = None) -> Path:
    """Log-log work-precision plot: the larger of the peak and exit-velocity
    errors against CPU time, one line per scheme through the medians over
    the round-off copies, with a bar from the best copy to the worst; the
    paper's method and the monolithic tolerances as points; runs whose
    worst copy miscounts the contacts are hollow.  Written whole through the
    checked writer (see :func:`write_csv` for ``path`` and ``folder``).
    Needs matplotlib (``pip install "cosim[plot]"``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    groups: dict[str, list[BenchRow]] = {}
    for r in rows:
        if r.status == "finished":
            groups.setdefault(r.label, []).append(r)
    floor = 1e-8
    spread = max((r.copies for r in rows), default=1)
    for label, rs in groups.items():
        x = [r.cpu_time_s for r in rs]
        y = [max(r.err_peak, r.err_exit_velocity, floor) for r in rs]
        lo = [max(_best(r.err_peak_best, r.err_peak), _best(r.err_exit_velocity_best,
                                                            r.err_exit_velocity), floor)
              for r in rs]
        hi = [max(_best(r.err_peak_worst, r.err_peak), _best(r.err_exit_velocity_worst,
                                                             r.err_exit_velocity), floor)
              for r in rs]
        marker = {"paper_rk45": "*", "monolithic": "s"}.get(label, "o")
        line, = ax.plot(x, y, marker=marker, ls="-" if len(rs) > 1 else "none", label=label)
        ax.errorbar(x, y, yerr=[[max(yi - li, 0.0) for yi, li in zip(y, lo)],
                                [max(hi_ - yi, 0.0) for yi, hi_ in zip(y, hi)]],
                    fmt="none", ecolor=line.get_color(), elinewidth=1.0, capsize=3)
        for r, xi, yi in zip(rs, x, y):
            if _best(r.err_count_worst, r.err_count):
                ax.plot([xi], [yi], marker=marker, mfc="white", mec=line.get_color(), ls="none")
            if label not in ("paper_rk45", "monolithic"):
                ax.annotate(f"{r.macro_step:.0e}", (xi, yi), fontsize=7,
                            textcoords="offset points", xytext=(3, 3))
    ax.axhline(0.01, color="grey", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("CPU time of the run [s]" + (", median" if spread > 1 else ""))
    ax.set_ylabel("max(peak, exit velocity) relative error")
    if spread > 1:
        ax.text(0.99, 0.01, f"median of {spread} round-off copies; bars: best to worst; "
                f"hollow: a copy miscounts", transform=ax.transAxes, ha="right", va="bottom",
                fontsize=7, color="dimgrey")
    ax.set_title(title or "work-precision")
    ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        return _write(path, folder, lambda fh: fig.savefig(fh, dpi=110, format="png"), "wb")
    finally:
        plt.close(fig)


def _best(x: float, fallback: float) -> float:
    """``x``, or ``fallback`` where a row has no band (NaN)."""
    return fallback if math.isnan(x) else x
