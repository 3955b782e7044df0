"""The one closed form (:func:`identification.model.piece_coefficients`), compiled by numba.

The environment's kernel (:mod:`rollenv.core`) and the maximum-likelihood
identification (:mod:`identification.ml`) both call :data:`piece`, so the
physics they integrate is the source in :mod:`identification.model`, not a
copy.  For numba the array helpers ``select`` and ``phi_functions`` become
scalar branches (only the branch that is used is computed).
"""

from __future__ import annotations

from typing import Any

import numba
import numba.extending

from identification import model

__all__ = ["piece"]


@numba.extending.overload(model.select)
def _select_scalar(condition: Any, if_true: Any, if_false: Any) -> Any:
    """Scalar ``select`` for numba: a branch, not a 0-d array per call."""

    def impl(condition: Any, if_true: Any, if_false: Any) -> Any:
        return if_true if condition else if_false

    return impl


_phi_taylor = numba.njit(cache=True, nogil=True)(model.phi_taylor)
_phi_direct = numba.njit(cache=True, nogil=True)(model.phi_direct)


@numba.extending.overload(model.phi_functions)
def _phi_functions_scalar(z: Any) -> Any:
    """Scalar ``phi_functions`` for numba: only the branch that is used is computed."""

    def impl(z: Any) -> Any:
        if abs(z) < model.PHI_TAYLOR_BELOW:
            return _phi_taylor(z)
        return _phi_direct(z)

    return impl


#: ``piece(alpha, theta_bar, beta_bar, alpha_bar, theta0, theta1, u_d, h) -> (E, c, A, B)``
#: for scalars, compiled (see :func:`identification.model.piece_coefficients`).
piece = numba.njit(cache=True, nogil=True)(model.piece_coefficients)
