"""mesh: scan preparation, alignment and binding, tissue volume and tets, facial regions.

Modules: ``scan_io`` (load/clean scans), ``remesh`` (hole closing, isotropic remeshing),
``align`` (Umeyama, per-axis scaling eqs 5.1-5.4, non-rigid refinement), ``binding``
(closest point, eqs 4.6-4.14), ``kinematic`` (shape-motion model, eqs 4.15-4.16), ``tissue``
(closed tissue surface), ``tetra`` (fTetWild tets, quality, node labels), ``regions``
(facial regions), ``params`` (stage parameter models, the materials file's too),
``topology`` (mesh combinatorics). Per-tet constants from the regions:
``physanim.fem.region_materials``.
"""
