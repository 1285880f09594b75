"""mesh: scan preparation, alignment and binding, tissue volume and tets, regional materials.

Modules: ``scan_io`` (load/clean scans), ``remesh`` (hole closing, isotropic remeshing),
``align`` (Umeyama, per-axis scaling eqs 5.1-5.4, non-rigid refinement), ``binding``
(closest point, eqs 4.6-4.14), ``kinematic`` (shape-motion model, eqs 4.15-4.16), ``tissue``
(closed tissue surface), ``tetra`` (fTetWild tets, quality, node labels), ``regions`` and
``materials`` (facial regions, per-tet constants), ``params`` (stage parameter models),
``topology`` (mesh combinatorics).
"""
