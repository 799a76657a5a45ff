"""The base class of the structural integrators, :class:`StructuralIntegrator`,
and the linear algebra they share: factorisation of a step's matrix (dense
or sparse), the generalized symmetric eigenproblem.

The load over a step and the state ``(u, v, a)`` are as stated in
:mod:`fem.integrators`.
"""
from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

__all__ = ["StructuralIntegrator", "SMALL_DENSE", "generalized_eigh"]

_CACHE_SIZE = 8     # step sizes whose operators are kept (oldest dropped first)



def _issparse(A) -> bool:
    """A scipy.sparse matrix (told without importing scipy.sparse)."""
    return hasattr(A, "tocsr")


def _dense(A):
    return A.toarray() if _issparse(A) else A


def _max_abs(A) -> float:
    """Largest magnitude of the entries of a dense or sparse matrix."""
    if _issparse(A):
        return float(abs(A).max()) if A.nnz else 0.0
    return float(np.abs(A).max(initial=0.0))


def _factorize(A):
    """Solver ``b -> A^{-1} b``: sparse LU, dense Cholesky if SPD, else dense LU."""
    import scipy.linalg as sla
    if _issparse(A):
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla
        return spla.splu(sp.csc_matrix(A)).solve
    if np.array_equal(A, A.T):
        try:
            c = sla.cho_factor(A, check_finite=False)
            return lambda b: sla.cho_solve(c, b, check_finite=False)
        except np.linalg.LinAlgError:
            pass
    lu = sla.lu_factor(A, check_finite=False)
    return lambda b: sla.lu_solve(lu, b, check_finite=False)


#: below this size a dense symmetric eigenproblem is solved by numpy, with no
#: scipy import: what a discrete chain needs
SMALL_DENSE = 32


def generalized_eigh(K, M):
    """Eigenvalues (ascending) and M-normalised vectors of ``K x = lam M x``
    for dense symmetric ``K`` and SPD ``M``: numpy's ``eigh`` after a
    Cholesky reduction when small (:data:`SMALL_DENSE`), scipy's otherwise."""
    n = K.shape[0]
    if n > SMALL_DENSE:
        from scipy.linalg import eigh
        return eigh(K, M)
    L = np.linalg.cholesky(M)
    Li = np.linalg.inv(L)
    lam, Y = np.linalg.eigh(Li @ K @ Li.T)
    return lam, Li.T @ Y


class StructuralIntegrator(ABC):
    """Base class of the integrators of ``M a + C v + K u = f(t)``.

    Parameters
    ----------
    M, C, K : (n, n) ndarray or scipy.sparse matrix
        Mass [kg], damping [N s/m] (``None`` for none) and stiffness [N/m]
        matrices; if any is sparse all are used as sparse CSR.

    Attributes
    ----------
    n_factorizations : int
        Step-size dependent operators built so far (factorisations or modal
        propagators); stepping again with a cached ``h`` does not add one.
    """

    order: ClassVar[float]
    name: ClassVar[str]

    def __init__(self, M, C, K):
        mats = {"M": M, "C": C, "K": K}
        sparse = any(_issparse(x) for x in mats.values())
        n = None
        for key, x in mats.items():
            if x is None and key == "C":
                continue
            if x is None:
                raise ValueError(f"`{key}` must be a square matrix, got None")
            if sparse:
                import scipy.sparse as sp
                x = sp.csr_matrix(x, dtype=float)
            else:
                x = np.asarray(x, dtype=float)
            if x.ndim != 2 or x.shape[0] != x.shape[1] or (n is not None and x.shape[0] != n):
                want = "a square matrix" if n is None else f"shape ({n}, {n}) like `M`"
                raise ValueError(f"`{key}` must be {want}, got shape {x.shape}")
            n = x.shape[0]
            mats[key] = x
        self.M, self.C, self.K, self.n = mats["M"], mats["C"], mats["K"], n
        self.n_factorizations = 0
        self._ops: dict[float, object] = {}
        self._m_solve = None
        self._omega_max = None

    # -- operators cached per step size --------------------------------------
    @abstractmethod
    def _build(self, h: float):
        """Operator for step ``h`` (a factorisation or modal propagator)."""

    def _operator(self, h):
        op = self._ops.get(h)
        if op is None:
            if not (isinstance(h, numbers.Real) and math.isfinite(h) and h > 0):
                raise ValueError(f"`h` must be > 0 s, got {h!r}")
            op = self._build(float(h))
            self.n_factorizations += 1
            if len(self._ops) >= _CACHE_SIZE:
                self._ops.pop(next(iter(self._ops)))
            self._ops[h] = op
        return op

    def _load(self, F):
        F = np.asarray(F, dtype=float)
        if F.ndim == 1:
            F = F[None]
        if F.ndim != 2 or F.shape[1] != self.n or not 1 <= F.shape[0] <= 3:
            raise ValueError(f"`F` must have shape (p + 1, {self.n}) with p <= 2, "
                             f"got {np.shape(F)}")
        return F

    # -- public interface -----------------------------------------------------
    @abstractmethod
    def step(self, u, v, a, h, F):
        """Advance ``(u, v, a)`` over ``[t, t + h]``.

        Parameters
        ----------
        u, v, a : (n,) ndarray
            Displacement [m], velocity [m/s] and acceleration [m/s^2] at ``t``
            (``a`` as carried by the scheme, see :meth:`initial_acceleration`).
        h : float
            Step [s].
        F : (p + 1, n) array_like, p <= 2
            Load coefficients [N]: ``f(t + s h) = sum_j F[j] s**j``.

        Returns
        -------
        u1, v1, a1 : (n,) ndarray
            New arrays at ``t + h``.
        """

    def initial_acceleration(self, u, v, f0):
        """Acceleration [m/s^2] solving ``M a0 = f0 - C v - K u`` (M factorised once)."""
        if self._m_solve is None:
            self._m_solve = _factorize(self.M)
        r = np.asarray(f0, dtype=float) - self.K @ u
        if self.C is not None:
            r = r - self.C @ v
        return self._m_solve(r)

    def max_stable_step(self) -> float:
        """Largest stable step [s]; ``math.inf`` for unconditionally stable schemes."""
        return math.inf

    def omega_max(self) -> float:
        """Highest undamped circular frequency [rad/s] of ``K phi = omega^2 M phi``
        (dense ``eigh``; for sparse n > 200 ``eigsh`` to a relative 1e-6, a Ritz
        value that errs low by ~1e-8 on a 3000-mass chain); computed once."""
        if self._omega_max is None:
            if _issparse(self.K) and self.n > 200:
                import scipy.sparse.linalg as spla
                lam = spla.eigsh(self.K, k=1, M=self.M, which="LA", tol=1e-6,
                                 ncv=min(self.n - 1, 40), return_eigenvectors=False)[0]
            else:
                import scipy.linalg as sla
                dense = [_dense(x) for x in (self.K, self.M)]
                lam = sla.eigh(*dense, eigvals_only=True,
                               subset_by_index=[self.n - 1, self.n - 1])[0]
            self._omega_max = math.sqrt(max(float(lam), 0.0))
        return self._omega_max

    def energy(self, u, v) -> float:
        """Mechanical energy ``v^T M v / 2 + u^T K u / 2`` [J]."""
        return 0.5 * float(v @ (self.M @ v)) + 0.5 * float(u @ (self.K @ u))
