"""Running a scene."""
from __future__ import annotations

import logging
import time

from .guard import Guard
from .recorder import Recorder
from .scene import Scene, load_scene
from .errors import SimulationError
from .schemes import Monolithic

__all__ = ["simulate", "run_scene"]

log = logging.getLogger(__name__)


def simulate(scene: Scene, *, scheme: str | None = None, progress=None,
             progress_interval: float = 0.2):
    """Run a validated scene and return its :class:`~cosim.result.SimulationResult`.

    Parameters
    ----------
    scene : Scene
    scheme : str, optional
        Another coupling scheme than the scene's.
    progress : callable, optional
        Called with a :class:`~cosim.recorder.Progress` (simulated time,
        end time, contact intervals begun, wall time) as the run goes, at most
        once per ``progress_interval`` seconds of wall-clock time.
    progress_interval : float
        [s]

    Raises
    ------
    UnsafeStepError
        If an explicit scheme's macro step is too large for a contact (the
        pre-flight check); nothing has run then.
    """
    system, sch = scene.build(scheme)
    if isinstance(sch, Monolithic):
        auto = False                       # it locates every switch itself
    else:                                  # embedded contacts: their integrator does
        auto = [c not in system.embedded for c in range(system.n_contacts)]
    rec = Recorder(system, scene.name, sch.name, scene.t_end, every=scene.output_every,
                   auto_edges=auto, progress=progress, progress_interval=progress_interval,
                   guard=Guard(system, scene.guard))
    cpu0 = time.process_time()
    status, message = "finished", ""
    counters = {}
    try:
        counters = sch.run(system, scene.t_end, rec)
    except SimulationError as exc:
        status, message = "failed", str(exc)
        log.error("%s", exc)
    return rec.finish(status, message, time.process_time() - cpu0, counters)


def run_scene(path, *, variant=None, scheme=None, overrides=()):
    """Load and run a scene file in one call."""
    return simulate(load_scene(path, variant, overrides, scheme))
