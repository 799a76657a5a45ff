"""Parameter studies: one scene run over a grid of variants and overrides.

:func:`sweep` runs every combination of a scene's variants and of values of
``--set`` keys, on this process, a local process pool, or a Dask distributed
cluster, and returns one record per point in grid order.  Each point gets a
run directory named from its parameters alone (``summary.json``,
``series.npz``, ``scene.toml`` and ``point.json``), so a sweep that is run
again skips the points already done; the records go to one CSV table.

The package is split by concern:

- :mod:`~cosim.studies.sweep.grid`: the grid (a product, each point made
  when asked for), its points and their names;
- :mod:`~cosim.studies.sweep.backends`: where the points run (this process,
  a process pool with time limits, Dask);
- :mod:`~cosim.studies.sweep.resume`: which points of a sweep folder are done
  (keyed on the content of every file a point reads and cosim's version);
- :mod:`~cosim.studies.sweep.table`: the records and the CSV table;
- :mod:`~cosim.studies.sweep.plot`: the figure;
- :mod:`~cosim.studies.sweep.study`: study files (the paper's figures 8 and 11);
- :mod:`~cosim.studies.sweep.driver`: :func:`sweep` itself.

The impact regime of a record is :func:`cosim.studies.metrics.impact_regime`
(offered here too, as before).

Neither Dask nor matplotlib is imported unless a sweep asks for a scheduler
or a plot.
"""
from cosim.scene.load import SceneError  # what a bad scene, grid or study file raises
from cosim.studies.sweep.backends import CONNECT_TIMEOUT_S, SweepError, default_workers
from cosim.studies.sweep.driver import (MAX_TIMEOUT_S, SweepEvent, SweepInterrupted, strike_names,
                                        sweep, sweep_folder)
from cosim.studies.sweep.grid import (LARGE_GRID, MAX_POINTS, Grid, Point, grid_points,
                                      parse_grid_option, point_name, split_values)
from cosim.studies.metrics import impact_regime  # its home is metrics; offered here as before
from cosim.studies.sweep.plot import plot_sweep
from cosim.studies.sweep.resume import DONE
from cosim.studies.sweep.study import Study, load_study, run_study
from cosim.studies.sweep.table import (PLOT, TABLE, TIMING_COLUMNS, columns, flatten, read_table,
                                       table_writer, write_table)

__all__ = ["Point", "Grid", "SweepEvent", "Study", "SweepError", "SweepInterrupted", "sweep", "grid_points",
           "strike_names", "split_values", "parse_grid_option", "point_name", "impact_regime", "flatten",
           "columns", "write_table", "read_table", "plot_sweep", "load_study", "run_study",
           "default_workers", "TIMING_COLUMNS", "TABLE", "PLOT", "DONE", "CONNECT_TIMEOUT_S",
           "sweep_folder", "table_writer", "LARGE_GRID", "MAX_POINTS", "MAX_TIMEOUT_S"]
