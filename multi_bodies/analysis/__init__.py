"""Trajectory analysis: pair correlation g(r), structure factor S(k), F(k, t) and mean-square displacements.

The room of doc/analysis.md (floor 5 of ARCHITECTURE.md, beside ``multi_bodies/run``): it reads saved
trajectories with the readers of ``multi_bodies.files.snapshots`` and never imports the advisor, the
ensembles or the scripts.

* :mod:`.trajectories`: frame sources (arrays, a run's ``.clones`` series or ``.config`` files) read
  in chunks, and :func:`.trajectories.analyse`, one pass over them that feeds every accumulator;
* :mod:`.pair_correlation`: g(r) in the plane (x, y) or in 3-d, minimum image on periodic axes;
* :mod:`.structure_factor`: S(k) on the box's wavevectors, radially binned, per species;
* :mod:`.time_correlations`: F(k, t) (self and collective) and the mean-square displacements;
* :mod:`.tables`: text tables and charts;
* :mod:`.hydrogrid`: the published HydroGrid options (``hydroGridOptions.nml``) mapped onto these
  analyses, and the writer wrapper that samples S(k) during a run.
"""
