"""core/blas_threads.py: one OpenBLAS thread inside the block, the previous count after it."""
import numpy as np

from markerless_mocap.core.blas_threads import blas_threads, current_blas_threads


def test_one_thread_inside_the_block_and_the_count_restored_after():
    before = current_blas_threads()
    with blas_threads(1) as found:
        inside = current_blas_threads()
        a = np.random.default_rng(0).normal(size=(300, 300))
        x = np.linalg.solve(a @ a.T + np.eye(300), np.ones(300))
    assert found == len(before)
    assert inside == [1] * len(before)
    assert current_blas_threads() == before
    np.testing.assert_allclose((a @ a.T + np.eye(300)) @ x, np.ones(300), atol=1e-8)
    # numpy's wheels bundle OpenBLAS on Linux: the helper must find it there, or it silently does nothing.
    import sys
    if sys.platform.startswith("linux"):
        assert found >= 1
