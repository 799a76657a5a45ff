"""What accuracy costs in time: work-precision studies of a scene.

:func:`run_bench` runs a scene's impact under several coupling schemes and
step sizes, and measures each run's CPU time and its errors against a fine
monolithic reference (cached per scene, variant and settings): C's peak
penetration, the count of its contacts, a joint's exit velocity at its last
release (:mod:`cosim.studies.metrics`) and the energy error.  The seed paper's own
method, the monolithic model under explicit RK45 with max step 1e-4 s, rtol
1e-4 and atol 1e-6 (MATLAB's ode45 with these settings), is the row
``paper_rk45``.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

from cosim.errors import SimulationError, UnsafeStepError
from cosim.studies.metrics import impact_metrics, relative_errors
from cosim.studies.strike import find_strike
from cosim.scene.run import simulate
from cosim.scene.load import load_scene

__all__ = ["BenchRow", "COLUMNS", "reference", "run_bench", "cheapest_within", "write_csv", "plot"]

#: columns of the CSV, in order
COLUMNS = ("scheme", "label", "macro_step", "tolerance", "cpu_time_s", "err_peak", "err_count",
           "err_exit_velocity", "err_energy", "status")

#: the reference: monolithic DOP853, every switch located, tight tolerances
REFERENCE = {"method": "DOP853", "rtol": 1e-11, "atol": 1e-14}

#: the seed paper's method (Lipinski: MATLAB ode45)
PAPER_RK45 = {"method": "RK45", "max_step": 1e-4, "rtol": 1e-4, "atol": 1e-6}


@dataclass(frozen=True)
class BenchRow:
    """One run of a work-precision study.  Errors are relative (peak, exit
    velocity, energy: drift over the initial energy) or absolute (count);
    NaN where the run did not finish."""

    scheme: str
    label: str
    macro_step: float
    tolerance: float
    cpu_time_s: float
    err_peak: float
    err_count: float
    err_exit_velocity: float
    err_energy: float
    status: str


def _metrics(res, contact, joint) -> dict:
    m = impact_metrics(res, contact, joint)
    e = res.summary["energy"]
    m["energy"] = e["max_abs_drift"] / abs(e["initial"]) if e["initial"] else math.nan
    return m


def _monolithic(options: dict) -> list[str]:
    """Overrides setting the monolithic scheme's options, in its own table so
    that they win over a scene's ``[scheme.monolithic]``."""
    return [f"scheme.monolithic.{k}={json.dumps(v)}" for k, v in options.items()]


def _key(scene, contact, joint) -> str:
    blob = json.dumps({"data": scene.data, "reference": REFERENCE, "contact": contact,
                       "joint": joint}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def reference(path, variant=None, contact=None, joint=None, overrides=(),
              cache_dir=None) -> dict:
    """Impact metrics of the fine monolithic reference, from the cache when
    the same scene (after variant and overrides) was benched before.

    ``contact`` and ``joint`` are those of :func:`run_bench`.

    Returns a dict with ``count``, ``peak``, ``exit_velocity``, ``energy``
    and the reference's ``cpu_time_s``.

    Raises
    ------
    SceneError
        If the scene has no such ``contact`` or ``joint``, or leaves one out
        and more than one (or no) choice (see :func:`find_strike`).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path, variant, list(overrides), "monolithic")
    contact, joint = find_strike(scene, contact, joint)
    cache = None
    if cache_dir is not None:
        cache = Path(cache_dir) / f"{scene.name}-{variant or 'default'}-" \
                                  f"{_key(scene, contact, joint)}.json"
        if cache.exists():
            return json.loads(cache.read_text())
    ov = list(overrides) + _monolithic(REFERENCE)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(load_scene(path, variant, ov, "monolithic"))
    if not res.success:
        raise SimulationError(f"the reference run failed: {res.message}")
    ref = _metrics(res, contact, joint)
    ref["cpu_time_s"] = res.summary["cpu_time_s"]
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache.with_suffix(".tmp")
        tmp.write_text(json.dumps(ref))
        tmp.replace(cache)
    return ref


def _row(path, variant, overrides, scheme, label, step, tol, ref, contact, joint) -> BenchRow:
    nan = math.nan
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = simulate(load_scene(path, variant, list(overrides), scheme))
    except UnsafeStepError:
        return BenchRow(scheme, label, step, tol, nan, nan, nan, nan, nan, "refused")
    if not res.success:
        return BenchRow(scheme, label, step, tol, res.summary["cpu_time_s"], nan, nan, nan, nan,
                        "failed")
    m = _metrics(res, contact, joint)
    err = relative_errors(m, ref)
    return BenchRow(scheme, label, step, tol, res.summary["cpu_time_s"], err["peak"],
                    err["count"], err["exit_velocity"], abs(m["energy"]), "finished")


def run_bench(path, variant=None, schemes=None, steps=None, contact=None, joint=None,
              overrides=(), tolerances=(1e-3, 1e-4, 1e-6, 1e-8), cache_dir=None,
              progress=None) -> tuple[dict, list[BenchRow]]:
    """A work-precision study of a scene.

    Parameters
    ----------
    path : str or Path
        The scene file.
    variant : str, optional
    schemes : list of str, optional
        Co-simulation schemes to sweep (default: the scene's own, if it is
        one, and ``implicit``).
    steps : list of float, optional
        Step sizes [s].  Where the scene sets ``scheme.contact_step``, the
        step in contact is varied (the long free-flight step stays);
        otherwise ``scheme.macro_step``.  Default: 1e-4, 5e-5, 2e-5, 1e-5.
    contact, joint : str, optional
        The contact whose peak penetration and count are compared, and the
        joint (``SUBSYSTEM/JOINT``) whose rate at its last release is.  Left
        out, the scene chooses them (:func:`cosim.studies.strike.find_strike`:
        its only contact, else its only contact of a multibody on a
        structure; the joint of the body that carries the contact's point).
    overrides : sequence of str
        ``key.path=value`` applied to every run.
    tolerances : sequence of float
        ``rtol`` of the extra monolithic (DOP853) rows.
    cache_dir : path, optional
        Where the reference is cached.
    progress : callable, optional
        Called with each finished :class:`BenchRow`.

    Returns
    -------
    reference : dict
    rows : list of BenchRow

    Raises
    ------
    SceneError
        If the scene has no such ``contact`` or ``joint``, or leaves one out
        and more than one (or no) choice.
    """
    scene = load_scene(path, variant, list(overrides))
    contact, joint = find_strike(scene, contact, joint)
    ref = reference(path, variant, contact, joint, overrides, cache_dir)
    if schemes is None:
        schemes = ([scene.scheme] if scene.scheme != "monolithic" else []) + ["implicit"]
        schemes = list(dict.fromkeys(schemes))
    steps = list(steps or (1e-4, 5e-5, 2e-5, 1e-5))
    varied = "contact_step" if scene.scheme_options.get("contact_step") else "macro_step"
    long_step = scene.scheme_options.get("macro_step") or 0.0
    runs = [("monolithic", "paper_rk45", math.nan, PAPER_RK45["rtol"], _monolithic(PAPER_RK45))]
    for tol in tolerances:
        runs.append(("monolithic", "monolithic", math.nan, tol, _monolithic(
            {"method": "DOP853", "rtol": tol, "atol": tol * 1e-3})))
    for name in schemes:
        for h in steps:
            ov = [f"scheme.{varied}={h}"]
            if varied == "contact_step" and long_step < h:
                ov.append(f"scheme.macro_step={h}")
            runs.append((name, name, h, math.nan, ov))
    rows = []
    for scheme, label, step, tol, ov in runs:
        row = _row(path, variant, list(overrides) + ov, scheme, label, step, tol, ref, contact,
                   joint)
        rows.append(row)
        if progress is not None:
            progress(row)
    return ref, rows


def within(row: BenchRow, accuracy: float) -> bool:
    """The row finished with the exact count and its peak and exit-velocity
    errors at most ``accuracy`` (relative)."""
    return (row.status == "finished" and row.err_count == 0
            and row.err_peak <= accuracy and row.err_exit_velocity <= accuracy)


def cheapest_within(rows, accuracy: float = 0.01) -> dict:
    """The cheapest row of each kind that meets ``accuracy``: ``cosim`` (any
    co-simulation scheme), ``monolithic`` and ``paper_rk45`` (None where no
    row meets it), and the CPU ratios of the first to the other two."""
    kinds = {"cosim": lambda r: r.scheme != "monolithic",
             "monolithic": lambda r: r.label == "monolithic",
             "paper_rk45": lambda r: r.label == "paper_rk45"}
    best = {}
    for kind, match in kinds.items():
        ok = [r for r in rows if match(r) and within(r, accuracy)]
        best[kind] = min(ok, key=lambda r: r.cpu_time_s) if ok else None
    c = best["cosim"]
    for kind in ("monolithic", "paper_rk45"):
        o = best[kind]
        best[f"ratio_{kind}"] = (c.cpu_time_s / o.cpu_time_s if c is not None and o is not None
                                 else math.nan)
    return best


def write_csv(rows, path) -> None:
    """The rows as CSV with :data:`COLUMNS`, written atomically."""
    path = Path(path)
    tmp = path.with_suffix(".tmp")
    with tmp.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow(asdict(r))
    tmp.replace(path)


def plot(rows, path, title="") -> None:
    """Log-log work-precision plot: the larger of the peak and exit-velocity
    errors against CPU time, one line per scheme, the paper's method and
    the monolithic tolerances as points; runs that miscount the contacts are
    hollow.  Needs matplotlib (``pip install "cosim[plot]"``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    groups: dict[str, list[BenchRow]] = {}
    for r in rows:
        if r.status == "finished":
            groups.setdefault(r.label, []).append(r)
    floor = 1e-8
    for label, rs in groups.items():
        x = [r.cpu_time_s for r in rs]
        y = [max(r.err_peak, r.err_exit_velocity, floor) for r in rs]
        marker = {"paper_rk45": "*", "monolithic": "s"}.get(label, "o")
        line, = ax.plot(x, y, marker=marker, ls="-" if len(rs) > 1 else "none", label=label)
        for r, xi, yi in zip(rs, x, y):
            if r.err_count:
                ax.plot([xi], [yi], marker=marker, mfc="white", mec=line.get_color(), ls="none")
            if label not in ("paper_rk45", "monolithic"):
                ax.annotate(f"{r.macro_step:.0e}", (xi, yi), fontsize=7,
                            textcoords="offset points", xytext=(3, 3))
    ax.axhline(0.01, color="grey", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("CPU time of the run [s]")
    ax.set_ylabel("max(peak, exit velocity) relative error")
    ax.set_title(title or "work-precision")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
