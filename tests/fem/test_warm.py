"""The setup's warm-up compiles the solve specialisations that the pipeline's runs use."""

import pytest

from physanim.fem import parallel_ldl
from physanim.fem.linsolve import has_cholmod
from physanim.fem.warm import warm_kernels


@pytest.mark.skipif(not has_cholmod(), reason="the float32 factor needs CHOLMOD")
def test_warm_up_runs_both_factor_precisions_and_compiles_their_solves():
    took = warm_kernels()
    assert set(took) == {"float32", "float64"}
    factor_dtypes = {str(sig[8].dtype) for sig in parallel_ldl._solve.signatures}  # vals
    assert {"float32", "float64"} <= factor_dtypes
