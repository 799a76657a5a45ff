"""What accuracy costs in time: work-precision studies of a scene.

:func:`run_bench` runs a scene's impact under several coupling schemes and
step sizes, and measures each run's CPU time and its errors against a fine
monolithic reference (cached per scene, variant and settings): C's peak
penetration, the count of its contacts, a joint's exit velocity at its last
release (:mod:`cosim.studies.metrics`) and the energy error.  The seed paper's own
method, the monolithic model under explicit RK45 with max step 1e-4 s, rtol
1e-4 and atol 1e-6 (MATLAB's ode45 with these settings), is the row
``paper_rk45``.

A train of impacts amplifies round-off, so a loose run's error is a
distribution, not a number: another machine's last bits can move it by more
than the run's own accuracy.  Each row is therefore run on the scene and on
``spread - 1`` copies whose initial state is moved by a few ulps
(:func:`cosim.studies.roundoff.spread`), and reports, per error, the median,
the best and the worst over the copies (the band), the contact counts'
range, and the median CPU time.  :func:`cheapest_within` judges a row by its
worst copy.  The reference stays one run: at rtol 1e-11 two copies of it
give the same count and differ by less than 1e-11 in peak and exit velocity
(``tests/test_work_precision_doc.py``), far below any row's error.

The reference cache (``cache_dir``; ``runs/.bench-cache`` for ``cosim
bench``) holds one JSON entry per reference, opened as an
:class:`~cosim.io.rundir.OutputFolder` (a link at its place is refused).  An
entry is used only when the key it stores equals this run's
(:func:`cache_key`: cosim's version, the SHA-256 of the scene file and of
every file it names, FMUs included (:mod:`cosim.scene.inputs`), the scene's
table after variant and overrides, the reference's settings, the contact
and the joint), its reference has the fields and types a reference has, and
its checksum matches its content.  Any other entry (not JSON, a list, cut
short, for other inputs, a number edited by hand) is never trusted: a
warning names the file, the reference is run again and the entry replaced.

Trust model: the cache is a convenience, not a signature.  Its checksum
catches damage and a number edited by hand; whoever can write the cache
folder can also write an entry whose checksum matches, and such an entry is
used as it is.  The folder is the user's own (as are the scene files), so
an entry forged that way is the user's own doing.
"""
from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import statistics
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

from cosim.errors import OutputError, SimulationError, UnsafeStepError
from cosim.io.rundir import OutputFolder, check_name
from cosim.scene.checks import SceneError
from cosim.studies.bench_cache import (CACHE_FORMAT, CACHE_MAX_BYTES, REFERENCE, _FIELDS,
                                        cache_entry, cache_key, entry_name, entry_problem,
                                        read_entry)
from cosim.studies.roundoff import OFFSETS, perturbed_overrides
from cosim.studies.metrics import impact_metrics, relative_errors
from cosim.studies.strike import find_strike
from cosim.scene.run import simulate
from cosim.scene.load import load_scene

__all__ = ["BenchRow", "COLUMNS", "MAX_SPREAD", "CACHE_FORMAT", "CACHE_MAX_BYTES", "REFERENCE",
           "reference", "run_bench", "within", "cheapest_within", "write_csv", "read_csv", "write_reference",
           "cache_key", "cache_entry", "entry_problem"]

#: columns of the CSV, in order: the first ten as before the copies (each
#: error now the median over them), then the copies and the band
COLUMNS = ("scheme", "label", "macro_step", "tolerance", "cpu_time_s", "err_peak", "err_count",
           "err_exit_velocity", "err_energy", "status", "copies", "finished",
           "err_peak_best", "err_peak_worst", "count_min", "count_max", "err_count_worst",
           "err_exit_velocity_best", "err_exit_velocity_worst", "err_energy_best",
           "err_energy_worst")

#: the most copies a row can run on: the scene and one per round-off offset
MAX_SPREAD = len(OFFSETS) + 1


#: the seed paper's method (Lipinski: MATLAB ode45)
PAPER_RK45 = {"method": "RK45", "max_step": 1e-4, "rtol": 1e-4, "atol": 1e-6}


@dataclass(frozen=True)
class BenchRow:
    """One row of a work-precision study: a scheme at one step or tolerance,
    run on the scene and its round-off copies.

    Errors are relative (peak, exit velocity, energy: drift over the initial
    energy) or absolute (count: contacts too many or too few).  ``err_*`` is
    the median over the copies, ``err_*_best`` and ``err_*_worst`` the
    smallest and largest; ``count_min`` and ``count_max`` are the contact
    counts the copies gave, ``err_count_worst`` the largest count error.
    ``cpu_time_s`` is the median CPU time of the copies.  With one copy
    (``copies`` = 1) median, best and worst are that run's.

    ``status`` is ``finished`` when every copy finished (``finished`` of
    ``copies`` did), else the status of the first that did not
    (``refused``: the scheme refused the step before running; ``failed`` or
    another status the run gave); the errors are then NaN: a band that lost
    a copy is no band.
    """

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
    copies: int = 1
    finished: int = 1
    err_peak_best: float = math.nan
    err_peak_worst: float = math.nan
    count_min: float = math.nan
    count_max: float = math.nan
    err_count_worst: float = math.nan
    err_exit_velocity_best: float = math.nan
    err_exit_velocity_worst: float = math.nan
    err_energy_best: float = math.nan
    err_energy_worst: float = math.nan


def _metrics(res, contact, joint) -> dict:
    m = impact_metrics(res, contact, joint)
    e = res.summary["energy"]
    m["energy"] = e["max_abs_drift"] / abs(e["initial"]) if e["initial"] else math.nan
    return m


def _monolithic(options: dict) -> list[str]:
    """Overrides setting the monolithic scheme's options, in its own table so
    that they win over a scene's ``[scheme.monolithic]``."""
    return [f"scheme.monolithic.{k}={json.dumps(v)}" for k, v in options.items()]


def reference(path, variant=None, contact=None, joint=None, overrides=(),
              cache_dir=None) -> dict:
    """Impact metrics of the fine monolithic reference, from the cache when
    the same inputs (the scene file and every file it names, cosim's
    version, variant and overrides) were benched before.

    ``contact`` and ``joint`` are those of :func:`run_bench`.  A cache entry
    is used only when it is fit (:func:`entry_problem`); an unfit one is
    named in a warning, run again and replaced (see the module's trust
    model).

    Returns a dict with ``count``, ``peak``, ``exit_velocity``, ``energy``
    and the reference's ``cpu_time_s``.

    Raises
    ------
    SceneError
        If the scene has no such ``contact`` or ``joint``, or leaves one out
        and more than one (or no) choice (see :func:`find_strike`).
    OutputError
        If the cache folder is a link or a file, or cannot be made or
        written.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path, variant, list(overrides), "monolithic")
    contact, joint = find_strike(scene, contact, joint)
    with contextlib.ExitStack() as stack:
        folder = name = key = None
        if cache_dir is not None:
            if os.path.islink(cache_dir):      # said plainly; the folder's own check holds
                raise OutputError(f"cannot use the reference cache {cache_dir}: it is a "
                                  f"symbolic link (cosim never writes through one); remove it")
            folder = stack.enter_context(OutputFolder(cache_dir, lock=False))
            key = cache_key(scene, variant, contact, joint)
            name = entry_name(scene, variant, key)
            got = read_entry(folder, name)
            problem = got if isinstance(got, str) else (
                None if got is None else entry_problem(got["entry"], key))
            if got is not None and problem is None:
                stored = got["entry"]["reference"]
                return {k: stored[k] if kind == "count" else float(stored[k])
                        for k, kind in _FIELDS.items()}
            if problem is not None:
                warnings.warn(f"the bench cache entry {folder.path_of(name)} {problem}: not "
                              f"used; the reference is run again and the entry replaced",
                              stacklevel=2)
        ref = _run_reference(path, variant, overrides, contact, joint)
        if folder is not None:
            folder.write(name, lambda fh: json.dump(cache_entry(key, ref), fh, indent=1), "w")
    return ref


def _run_reference(path, variant, overrides, contact, joint) -> dict:
    """Run the reference (:data:`REFERENCE`) and return its metrics."""
    ov = list(overrides) + _monolithic(REFERENCE)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(load_scene(path, variant, ov, "monolithic"))
    if not res.success:
        raise SimulationError(f"the reference run failed: {res.message}")
    ref = _metrics(res, contact, joint)
    ref["cpu_time_s"] = res.summary["cpu_time_s"]
    return ref


def write_reference(ref: dict, path, folder: OutputFolder | None = None) -> Path:
    """The reference's metrics (as :func:`reference` returns them) as JSON,
    written whole through the checked writer (see :func:`write_csv` for
    ``path`` and ``folder``)."""
    from cosim.io.strict_json import json_writer
    return _write(path, folder, json_writer(ref, indent=1), "w")


def _once(path, variant, overrides, scheme, ref, contact, joint) -> tuple:
    """One run of a row's copy: (status, CPU time, metrics and errors or None)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = simulate(load_scene(path, variant, list(overrides), scheme))
    except UnsafeStepError:
        return "refused", math.nan, None
    cpu = res.summary["cpu_time_s"]
    if not res.success:
        # the status the run gave (``failed``, ``error``), never ``finished``
        status = res.status if res.status != "finished" else "failed"
        return status, cpu, None
    m = _metrics(res, contact, joint)
    err = relative_errors(m, ref)
    err["energy"] = abs(m["energy"])
    return "finished", cpu, {"count": m["count"], **{f"err_{k}": v for k, v in err.items()}}


def _row(path, variant, overrides, copies, scheme, label, step, tol, ref, contact,
         joint) -> BenchRow:
    """A row: the run on each copy (``copies``: the overrides that make each),
    and the band of their errors."""
    nan = math.nan
    runs = [_once(path, variant, list(overrides) + list(c), scheme, ref, contact, joint)
            for c in copies]
    done = [m for status, _, m in runs if status == "finished"]
    cpus = [cpu for _, cpu, _ in runs if not math.isnan(cpu)]
    cpu = statistics.median(cpus) if cpus else nan
    k = len(runs)
    if len(done) < k:
        status = next(status for status, _, _ in runs if status != "finished")
        return BenchRow(scheme, label, step, tol, cpu, nan, nan, nan, nan, status, k, len(done))

    def band(key):
        v = [m[key] for m in done]
        if any(math.isnan(x) for x in v):     # a copy that never released: no band
            return nan, nan, nan
        return float(statistics.median(v)), float(min(v)), float(max(v))
    peak, ev, energy = band("err_peak"), band("err_exit_velocity"), band("err_energy")
    dc = band("err_count")
    counts = [float(m["count"]) for m in done]
    return BenchRow(scheme, label, step, tol, cpu, peak[0], dc[0], ev[0], energy[0], "finished",
                    k, len(done), peak[1], peak[2], min(counts), max(counts), dc[2], ev[1],
                    ev[2], energy[1], energy[2])


def _copies(scene, spread: int) -> list[list[str]]:
    """The ``--set`` overrides of the scene (none) and its ``spread - 1``
    round-off copies (:data:`cosim.studies.roundoff.OFFSETS` ulps)."""
    if isinstance(spread, bool) or not isinstance(spread, int) \
            or not 1 <= spread <= MAX_SPREAD:
        raise ValueError(f"`spread` must be a whole number of copies from 1 to {MAX_SPREAD} "
                         f"(the scene and one copy per round-off offset), got {spread!r}")
    try:
        return [[]] + [perturbed_overrides(scene, k) for k in OFFSETS[:spread - 1]]
    except ValueError as exc:
        raise SceneError(scene.path, "", f"`spread` = {spread} needs copies moved by "
                         f"round-off: {str(exc).split(': ', 1)[-1]}; `spread` = 1 (`--spread 1`) "
                         f"runs the scene alone") from None


def _runs(scene, schemes=None, steps=None, tolerances=(1e-3, 1e-4, 1e-6, 1e-8),
          paper: bool = True) -> list[tuple]:
    """The rows of :func:`run_bench` (its arguments of the same names):
    (scheme, label, step, tolerance, overrides) each."""
    if schemes is None:     # an explicit scheme too: the cheapest within 1 % may be one
        schemes = ([scene.scheme] if scene.scheme != "monolithic" else []) + [
            "gauss_seidel", "implicit"]
        schemes = list(dict.fromkeys(schemes))
    steps = list(steps or (1e-4, 5e-5, 2e-5, 1e-5))
    varied = "contact_step" if scene.scheme_options.get("contact_step") else "macro_step"
    long_step = scene.scheme_options.get("macro_step") or 0.0
    runs = [("monolithic", "paper_rk45", math.nan, PAPER_RK45["rtol"], _monolithic(PAPER_RK45))
            ] if paper else []
    for tol in tolerances:
        runs.append(("monolithic", "monolithic", math.nan, tol, _monolithic(
            {"method": "DOP853", "rtol": tol, "atol": tol * 1e-3})))
    for name in schemes:
        for h in steps:
            ov = [f"scheme.{varied}={h}"]
            if varied == "contact_step" and long_step < h:
                ov.append(f"scheme.macro_step={h}")
            runs.append((name, name, h, math.nan, ov))
    return runs


def run_bench(path, variant=None, schemes=None, steps=None, contact=None, joint=None,
              overrides=(), tolerances=(1e-3, 1e-4, 1e-6, 1e-8), cache_dir=None,
              progress=None, spread: int = 3, paper: bool = True,
              ref: dict | None = None) -> tuple[dict, list[BenchRow]]:
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
    spread : int
        Copies each row runs on: the scene and ``spread - 1`` copies moved
        by round-off (1 to :data:`MAX_SPREAD`; 1 is a single run).
    paper : bool
        Whether to run the ``paper_rk45`` row.
    ref : dict, optional
        The reference's metrics (as :func:`reference` returns them), when
        known; otherwise it is run (or read from ``cache_dir``).

    Returns
    -------
    reference : dict
    rows : list of BenchRow

    Raises
    ------
    ValueError
        If ``spread`` is not a whole number from 1 to :data:`MAX_SPREAD`.
    SceneError
        If the scene has no such ``contact`` or ``joint``, or leaves one out
        and more than one (or no) choice; if ``spread`` > 1 and the scene
        gives no nonzero initial state to move by round-off.
    """
    scene = load_scene(path, variant, list(overrides))
    copies = _copies(scene, spread)
    contact, joint = find_strike(scene, contact, joint)
    if ref is None:
        ref = reference(path, variant, contact, joint, overrides, cache_dir)
    runs = _runs(scene, schemes, steps, tolerances, paper)
    rows = []
    for scheme, label, step, tol, ov in runs:
        row = _row(path, variant, list(overrides) + ov, copies, scheme, label, step, tol, ref,
                   contact, joint)
        rows.append(row)
        if progress is not None:
            progress(row)
    return ref, rows


def within(row: BenchRow, accuracy: float) -> bool:
    """Every copy of the row finished with the exact count and its peak and
    exit-velocity errors at most ``accuracy`` (relative): the worst copy
    decides."""
    return (row.status == "finished" and row.err_count_worst == 0
            and row.err_peak_worst <= accuracy and row.err_exit_velocity_worst <= accuracy)


def cheapest_within(rows, accuracy: float = 0.01) -> dict:
    """The cheapest row of each kind whose worst copy meets ``accuracy``
    (:func:`within`): ``cosim`` (any co-simulation scheme), ``monolithic``
    and ``paper_rk45`` (None where no row meets it), and the CPU ratios
    (median CPU) of the first to the other two."""
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


def _write(path, folder: OutputFolder | None, write, mode: str) -> Path:
    """Write ``path`` whole through :meth:`cosim.io.rundir.OutputFolder.write`:
    as the name ``path`` in ``folder`` (open, its lock held by the caller),
    or, without ``folder``, into ``path``'s folder, opened and locked for
    the write."""
    if folder is not None:
        return folder.write(check_name(str(path), folder.path), write, mode)
    path = Path(path)
    with OutputFolder(path.parent) as own:
        return own.write(path.name, write, mode)


def write_csv(rows, path, folder: OutputFolder | None = None) -> Path:
    """The rows as CSV with :data:`COLUMNS`, written whole through the
    checked writer (:class:`cosim.io.rundir.OutputFolder`): a link planted
    at the name is replaced, never followed.

    Parameters
    ----------
    rows : sequence of BenchRow
    path : path-like or str
        The file; with ``folder``, its plain name in that folder.
    folder : OutputFolder, optional
        The open output folder whose lock the caller holds; without it,
        ``path``'s folder is opened and locked for the write.

    Raises
    ------
    OutputError
        If the name is no plain file name, the folder is a link or a file,
        another cosim process holds its lock, or the file cannot be written.
    """
    def write(fh):
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow(asdict(r))
    return _write(path, folder, write, "w")


def read_csv(path) -> list[BenchRow]:
    """The rows of a CSV that :func:`write_csv` wrote (a published run's)."""
    types = {f: t for f, t in BenchRow.__annotations__.items()}
    rows = []
    with open(path, newline="") as fh:
        for rec in csv.DictReader(fh):
            rows.append(BenchRow(**{k: (v if types[k] == "str" else
                                        int(v) if types[k] == "int" else float(v))
                                    for k, v in rec.items()}))
    return rows
