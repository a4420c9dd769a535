"""The viewshed family: every computation that looks from eyes over a whole grid.

* :mod:`.sweep`: :func:`~terrainvis.visibility.viewshed`, the exact viewshed of one
  eye (a sweep on a HeightGrid, the pair engines on a TIN), its output modes and field of
  view;
* :mod:`.output_modes`: what a viewshed can answer besides visible/blocked (the lowest
  visible height of a target, the angle to the horizon);
* :mod:`.field_of_view`: the eye's field of view (azimuth and elevation limits, ranges);
* :mod:`.many`: the runner of many viewsheds of one terrain, on threads, processes or a
  dask cluster, for
* :mod:`.cumulative` (the count of eyes that see each cell),
  :mod:`.observers` (the observer sets and the intervisibility network) and
  :mod:`.siting` (choosing observers that cover the most);
* the sweep's numba kernels, split by concern: :mod:`._geometry_kernels`,
  :mod:`._walk_kernels`, :mod:`._bound_kernels`, :mod:`._sector_kernels`.

The public names are those of :mod:`terrainvis.visibility` (and :mod:`terrainvis`);
this package's modules are where they live.
"""
