"""`cosim sweep`: the grid and its options checked, the sweep's folder held
from its first point to its figure, the progress, the listing, and the stop
on SIGTERM and SIGHUP (:mod:`cosim.studies.sweep` does the work)."""
from __future__ import annotations

import contextlib
import os
import signal
import sys
from pathlib import Path

from cosim.cli.terminal import _on_terminal, _raw

__all__: list[str] = []


def _cmd_sweep(args) -> int:
    from cosim.studies import sweep as sw
    from cosim.studies.sweep.driver import _check_options

    from cosim.errors import shown
    from cosim.scene.shipped import find_study, not_found, scene_file

    if args.study is not None:
        path = find_study(args.study)
        if not args.study or not path.exists():
            why = ("the study is an empty name" if not args.study else
                   f"{shown(args.study)}: cannot be read: {not_found(args.study, 'studies')}")
            print(f"error: {why}", file=sys.stderr)
            return 2
        study = sw.load_study(path)
        if args.scene or args.variants or args.set:
            print("error: --study fixes the scene, its variants and its values; give "
                  "none of SCENE, --variants, --set with it", file=sys.stderr)
            return 2
        scene, variants, grid = study.scene, list(study.variants), study.grid
        contact, joint = study.contact, study.joint
        timeout = args.timeout if args.timeout is not None else study.timeout
        default_out = Path("runs") / study.name
    elif args.scene is not None:
        study = None
        scene = scene_file(args.scene)        # a path, or the name of a shipped scene
        variants = [v for v in (args.variants or "").split(",") if v]
        grid = {}
        try:
            for text in args.set or ():
                key, values = sw.parse_grid_option(text)
                if key in grid:
                    raise ValueError(f"`{key}` is given twice; give its values in one --set")
                grid[key] = values
        except ValueError as exc:
            print(f"error: --set: {exc}", file=sys.stderr)
            return 2
        contact, joint = args.contact, args.joint
        timeout = args.timeout
        default_out = Path("runs") / f"{Path(scene).stem}-sweep"
    else:
        print("error: give a SCENE or --study", file=sys.stderr)
        return 2
    try:
        _check_names(scene, variants if study is None else [], args.scheme)
        n = len(sw.grid_points(variants or None, grid))
        workers = args.workers if args.workers is not None else sw.default_workers()
        _check_options(workers, timeout, ("--workers", "--timeout"))
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.accuracy is not None:
        from cosim.studies.accurate import conflicts
        from cosim.studies.choose import DOUBLE_PRECISION_FLOOR
        why = conflicts([f"{k}={','.join(map(str, v))}" for k, v in grid.items()], "--accuracy")
        if why is None and args.accuracy < DOUBLE_PRECISION_FLOOR:
            why = (f"--accuracy {args.accuracy:.3g} lies below {DOUBLE_PRECISION_FLOOR:g}, the "
                   f"smallest relative accuracy a run in double precision can be asked "
                   f"(`cosim.studies.choose.DOUBLE_PRECISION_FLOOR`)")
        if why is not None:
            print(f"error: {why}", file=sys.stderr)
            return 2
    if n > sw.LARGE_GRID and not args.yes:
        print(f"error: the sweep has {n} points, more than {sw.LARGE_GRID}: each runs and gets "
              f"a folder of its own; check --set and --variants, or pass --yes to run them "
              f"all", file=sys.stderr)
        return 2
    contact, joint = sw.strike_names(scene, variants, contact, joint)
    out = Path(args.out) if args.out else default_out
    where = (f"Dask scheduler {args.scheduler}" if args.scheduler
             else f"{workers} process(es)" if workers > 1 else "this process")
    print(f"sweep {shown(os.path.normpath(scene), 500)}: {n} point(s) on {where}, into {out}",
          flush=True)
    with sw.sweep_folder(out) as folder:        # held from the first point to the figure
        return _sweep_into(folder, args, study, scene, variants, grid, contact, joint,
                           workers, timeout, n)


def _check_names(scene, variants, scheme) -> None:
    """Refuse, before any point runs, a `--scheme` no scheme has and a name
    of `--variants` the scene has no variant of (a ValueError naming the
    option and the known names).  A scene that cannot be read is left to
    its points, which say why."""
    from cosim.errors import shown
    if scheme is not None:
        from cosim.cli.bench_command import _check_scheme
        _check_scheme(scheme, "--scheme")
    if variants:
        from cosim.scene.shipped import scene_variants
        known, _ = scene_variants(scene)
        unknown = [v for v in variants if v not in known]
        if known and unknown:
            raise ValueError(f"--variants: {shown(str(scene), 500)} has no variant "
                             f"{shown(repr(unknown[0]))}; its variants are {list(known)}")


def _sweep_into(folder, args, study, scene, variants, grid, contact, joint, workers, timeout,
                n) -> int:
    """`cosim sweep` once its folder is held: run, list, draw."""
    from cosim.studies import sweep as sw

    out = folder.path
    bar = _SweepProgress(args.quiet, n)
    stopped = None
    try:
        with _stop_signals_interrupt() as got:
            rows = sw.sweep(scene, variants=variants or None, grid=grid, scheme=args.scheme,
                            accuracy=args.accuracy,
                            workers=workers, scheduler=args.scheduler, out=folder,
                            retry_failed=args.retry_failed, contact=contact, joint=joint,
                            progress=bar, timeout=timeout)
    except (ImportError, sw.SweepError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except sw.SweepInterrupted as exc:
        rows, stopped = exc.rows, got[0] if got else exc.signal_name
    finally:
        bar.close()
    listed = rows if len(rows) <= _LISTED else [r for r in rows if r["status"] != "finished"]
    for r in listed[:_LISTED]:
        count = r.get(f"contacts.{contact}.count")
        line = f"  {r['point']:<40} {r['status']:<9}"
        if count is not None:
            line += f" {contact}: {count} contact(s)"
        if r.get("impact.regime"):
            line += f", {r['impact.regime']}"
        if r["status"] != "finished" and r["message"]:
            line += f"  ({r['message']})"
        print(line)
    if len(listed) < len(rows) or len(listed) > _LISTED:
        print(f"  ... {len(rows) - min(len(listed), _LISTED)} more point(s) in "
              f"{out / sw.TABLE}")
    print(f"{sum(r['status'] == 'finished' for r in rows)} of {len(rows)} point(s) finished"
          + (f", {bar.skipped} done before (not run again)" if bar.skipped else "")
          + (f", {bar.rerun} run again (their inputs changed or their folders were damaged)"
             if bar.rerun else ""))
    print(f"wrote {out / sw.TABLE}")
    if stopped is not None:
        never = n - len(rows)
        print(f"error: the sweep was stopped ({stopped}); the points that had not ended are "
              f"`interrupted` in {out / sw.TABLE}"
              + (f" ({never} never started are left out)" if never else "")
              + "; sweep again to run them", file=sys.stderr)
        return 128 + int(getattr(signal, stopped))
    if not args.no_plot and not any(r["status"] == "finished" for r in rows):
        # nothing to draw: no empty figure, and none of an earlier sweep left to mislead
        folder.remove(sw.PLOT)
        print(f"no plot: no point finished (their messages are in {out / sw.TABLE})")
    elif not args.no_plot:
        try:
            png = sw.plot_sweep(rows, folder.path_of(sw.PLOT), contact=contact,
                                x=study.x if study else None,
                                x_scale=study.x_scale if study else 1.0,
                                x_label=study.x_label if study else None,
                                title=study.title if study else f"{Path(scene).stem} sweep")
            print(f"wrote {png}")
        except ImportError:
            print('no plot: matplotlib is not installed (pip install "cosim[plot]")',
                  file=sys.stderr)
    return 0 if all(r["status"] == "finished" for r in rows) else 1


#: most points `cosim sweep` lists one per line (beyond it, those that did not finish)
_LISTED = 200


class _StopSignal(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where the main thread is, as Ctrl-C is."""

    def __init__(self, name: str):
        super().__init__(name)
        self.signal_name = name


@contextlib.contextmanager
def _stop_signals_interrupt():
    """Within: SIGTERM and SIGHUP (a scheduler's stop, `timeout`, a closed
    terminal) interrupt as Ctrl-C does, so that what ran is kept and the
    workers are ended (a second signal is noted, not raised, so the clean-up
    runs to its end); the handlers before are restored after.  Yields the
    list of the names of the signals received."""
    got: list[str] = []

    def handler(signum, frame):
        got.append(signal.Signals(signum).name)
        if len(got) == 1:           # a second one must not cut the clean-up short
            raise _StopSignal(got[-1])

    saved = {}
    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is not None:
            saved[sig] = signal.signal(sig, handler)
    try:
        yield got
    finally:
        for sig, old in saved.items():
            signal.signal(sig, old)


class _SweepProgress:
    """A sweep's progress: a tqdm bar on a terminal when tqdm is installed,
    else one line per point on stderr; nothing when quiet."""

    def __init__(self, quiet: bool, total: int):
        self.quiet, self.skipped, self.rerun, self._bar = quiet, 0, 0, None
        if not quiet and _on_terminal():
            try:
                from tqdm import tqdm
                self._bar = tqdm(total=total, unit="point", file=_raw(sys.stderr))
            except ImportError:
                pass

    def __call__(self, ev) -> None:
        self.skipped += ev.skipped
        self.rerun += bool(ev.note)
        if self.quiet:
            return
        note = "done before" if ev.skipped else ev.status
        if self._bar is not None:
            self._bar.set_postfix_str(f"{ev.point.name}: {note}", refresh=False)
            self._bar.update(1)
            if ev.note:
                self._bar.write(f"{ev.point.name}: {ev.note}")
            if ev.status != "finished":
                self._bar.write(f"{ev.point.name}: {ev.status}: {ev.message}")
        else:
            print(f"[{ev.done}/{ev.total}] {ev.point.name}: {note}"
                  + (f" ({ev.note})" if ev.note else ""), file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
