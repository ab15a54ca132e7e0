"""The SAD kernel's winners pass compiles to vector code (issue 13).

A numba or LLVM upgrade can silently stop vectorizing a hot loop: with the left winner's reduction and the right
pixels' running minima in one loop, numba 0.68 vectorized neither and the dense disparity took 2.1 times as long,
with identical outputs, so no result test notices; and a search for the left winner's lane ran in 64-bit lanes.
This compiles the pass afresh with the kernel's options (the cached code cannot be inspected) and looks in its
assembly for 256-bit minima of both: unsigned 16-bit for the right pixels' running minima, signed 32-bit for the
left winners' keys.
"""

import platform

import numpy as np
import pytest
from numba import njit

from stablemarks.vision import area_stereo

pytestmark = pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="x86 assembly")


def _has_avx2() -> bool:
    import llvmlite.binding as ll

    return bool(ll.get_host_cpu_features().get("avx2", False))


@pytest.mark.skipif(not _has_avx2(), reason="needs AVX2")
def test_winners_pass_is_vectorized():
    fn = njit(**{**area_stereo._NJ, "cache": False})(area_stereo._winners.py_func)
    u64 = np.uint64
    n_cols, n_disp = 64, 32
    stride = (n_disp // 16 + 1) * 16
    costs = np.zeros(n_cols * stride, np.uint16)
    fn(costs, np.zeros(n_cols, np.int32), np.zeros((2, n_cols), np.uint16), np.zeros(2 * n_cols, np.uint16),
       np.zeros(2 * n_cols, np.uint16), np.array([[1, 2, 0, n_disp]], np.int64), 1, u64(0), u64(n_disp), u64(stride),
       np.arange(n_disp, dtype=np.uint16), np.arange(n_disp, dtype=np.int32), np.int32(64))  # fmt: skip
    lines = fn.inspect_asm(fn.signatures[0]).splitlines()
    for op, what in (("vpminuw", "the right pixels' running minima"), ("vpminsd", "the left winners' keys")):
        # 256-bit vectors or wider: LLVM takes 512-bit ones (%zmm) where the CPU has AVX-512 (AMD Zen 4)
        assert any(op in line and ("%ymm" in line or "%zmm" in line) for line in lines), \
            f"{what} no longer compile to 256-bit (or wider) vectors"
