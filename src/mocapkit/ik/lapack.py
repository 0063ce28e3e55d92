"""LAPACK's dgesvd without U, callable from compiled kernels (the SDLS step's thin SVD)."""

from __future__ import annotations

from typing import Any

import llvmlite.binding
import numba
import numpy as np
from numba.core import types as nb_types
from numba.extending import get_cython_function_address
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


# LAPACK's dgesvd from SciPy's Cython bindings, bound by symbol name (not by address) so
# the kernels that call it stay in Numba's on-disk cache. ``np.linalg.svd`` in Numba
# always forms the thin U (dgesdd, jobz="S"); SDLS needs only the singular values, V and
# the few numbers of each term that ``u_i = J_w v_i / sigma_i`` gives (`sdls_nb`).
_DGESVD_SYMBOL = "mocapkit_sdls_dgesvd"
llvmlite.binding.add_symbol(
    _DGESVD_SYMBOL, get_cython_function_address("scipy.linalg.cython_lapack", "dgesvd")
)
_dgesvd: Any = nb_types.ExternalFunction(_DGESVD_SYMBOL, nb_types.void(*([nb_types.voidptr] * 14)))
#: ``jobu``, ``jobvt`` of dgesvd: no U, the first min(m, n) rows of V^T.
_JOB_NONE = ord("N")
_JOB_THIN = ord("S")


@numba.njit(cache=True)
def thin_svd_v_nb(a: FloatArray, s: FloatArray, vt: FloatArray) -> None:
    """Singular values and right singular vectors of an (m, n) matrix, LAPACK dgesvd.

    ``a`` (n, m) is the matrix in column-major order (``a[j, r]`` its entry ``(r, j)``)
    and is overwritten. With ``jobu="N"``, ``jobvt="S"``: ``s`` (k,) descending and
    ``vt`` (n, k) with ``vt[j, i]`` the component ``j`` of ``v_i``, ``k = min(m, n)``.
    Raises ``np.linalg.LinAlgError`` where the QR iteration does not converge.
    """
    n_c, n_rows = a.shape
    k = min(n_rows, n_c)
    ints = np.empty(7, dtype=np.int32)  # m, n, lda, ldu, ldvt, lwork, info
    lwork = 8 * (n_rows + n_c)
    work = np.empty(lwork)
    u_dummy = np.empty(1)
    jobs = np.empty(2, dtype=np.uint8)
    jobs[0] = _JOB_NONE
    jobs[1] = _JOB_THIN
    ints[0] = n_rows
    ints[1] = n_c
    ints[2] = n_rows
    ints[3] = 1
    ints[4] = k
    ints[5] = lwork
    ints[6] = 0
    _dgesvd(
        jobs[0:].ctypes,
        jobs[1:].ctypes,
        ints[0:].ctypes,
        ints[1:].ctypes,
        a.ctypes,
        ints[2:].ctypes,
        s.ctypes,
        u_dummy.ctypes,
        ints[3:].ctypes,
        vt.ctypes,  # V^T (k, n) column-major: vt[j, i] = V^T[i, j]
        ints[4:].ctypes,
        work.ctypes,
        ints[5:].ctypes,
        ints[6:].ctypes,
    )
    if ints[6] != 0:
        raise np.linalg.LinAlgError("SVD did not converge")


__all__ = ["thin_svd_v_nb"]
