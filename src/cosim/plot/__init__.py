"""Pictures of a run directory: time histories and an animation.

Reads what ``cosim run`` writes (``summary.json``, ``series.npz`` and, for
the animation, ``scene.toml``) and draws, in the manner of the seed paper's
figures (Lipinski, figs. 5-11): contact penetrations with the contact
intervals shaded, contact forces, joint velocities, structure DOFs and the
energy ledger.  A partial run (status not ``finished``, or series that stop
before the scene's end time) is drawn as far as it goes and marked
incomplete in every title.

Needs matplotlib (the ``plot`` extra).  Figures are drawn on matplotlib's
Agg canvas directly, without pyplot, so no global backend is chosen and no
window opens.  Nothing here prints: the paths written are returned.

The run directory is read in :mod:`cosim.plot.run_data`, the time histories
drawn in :mod:`cosim.plot.figures`, the animation in
:mod:`cosim.plot.animation`.
"""
from __future__ import annotations

from cosim.plot.animation import animate_run
from cosim.plot.figures import FORMATS, plot_run
from cosim.plot.run_data import PlotError, RunData, load_run

__all__ = ["FORMATS", "PlotError", "RunData", "load_run", "plot_run", "animate_run"]
