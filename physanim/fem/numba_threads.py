"""Choose numba's threading layer for the FEM's parallel kernels (import before compiling).

numba tries TBB first; a TBB older than it needs (open3d and fTetWild bring one) makes it warn
on every first parallel launch before falling back. OpenMP first, then TBB, then numba's own
workqueue (which is not safe for concurrent launches from several Python threads).
"""

import numba

numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]
