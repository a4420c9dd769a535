"""The terrain core: the two terrain models and what every other part builds on.

:mod:`~terrainvis.core.terrain` (:class:`HeightGrid`, :class:`TIN`), their meshes
(:mod:`~terrainvis.core.mesh`), random points on them (:mod:`~terrainvis.core.sampling`),
the bundled and synthetic terrains (:mod:`~terrainvis.core.synthetic`), how far a
simplification is from its original (:mod:`~terrainvis.core.deviation`), how many verdicts
agree (:mod:`~terrainvis.core.metrics`), and the shared services: argument checks
(:mod:`~terrainvis.core.validate`), memory (:mod:`~terrainvis.core.memory`), interrupts
(:mod:`~terrainvis.core.interrupt`), safe writes (:mod:`~terrainvis.core.fileio`),
xarray (:mod:`~terrainvis.core.dataarray`) and the runner of independent work
(:mod:`~terrainvis.core.runner`). Nothing here imports from the other parts of
terrainvis except :mod:`terrainvis.errors` and :mod:`terrainvis.tolerances`.
"""
