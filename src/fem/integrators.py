"""Time integrators for linear structural dynamics ``M a + C v + K u = f(t)``.

Over one step ``[t, t + h]`` the load is a polynomial of degree ``p <= 2`` in the
normalised time ``s = (t' - t) / h``: ``f(t + s h) = sum_j F[j] s**j`` with ``F`` of
shape ``(p + 1, n)`` [N].  The state is ``(u, v, a)``: displacement [m], velocity
[m/s] and the acceleration the scheme carries [m/s^2].  Registry
:data:`STRUCTURAL_INTEGRATORS`: ``newmark`` [1]_, ``hht_alpha`` [2]_,
``generalized_alpha`` [3]_ and ``central_difference`` are one algorithm (the form of
[3]_) with different parameters, its matrix factorised once per step size; ``exact``
steps a linear model with modal damping exactly and is the default where it applies.

References
----------
.. [1] N. M. Newmark, "A method of computation for structural dynamics", J. Eng.
   Mech. Div. ASCE 85(EM3), 67-94, 1959.
.. [2] H. M. Hilber, T. J. R. Hughes, R. L. Taylor, "Improved numerical dissipation
   for time integration algorithms in structural dynamics", Earthquake Eng. Struct.
   Dyn. 5, 283-292, 1977.
.. [3] J. Chung, G. M. Hulbert, "A time integration algorithm for structural dynamics
   with improved numerical dissipation: the generalized-alpha method", J. Appl.
   Mech. 60, 371-375, 1993.
.. [4] T. J. R. Hughes, "The Finite Element Method", Prentice-Hall, 1987, ch. 9.
"""
from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from .checks import real

__all__ = ["StructuralIntegrator", "Newmark", "HHTAlpha", "GeneralizedAlpha",
           "CentralDifference", "ExactModal", "STRUCTURAL_INTEGRATORS",
           "get_structural_integrator"]

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


class _AlphaFamily(StructuralIntegrator):
    """Generalized-alpha form [3]_ of the Newmark-family schemes.

    With ``x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n``, one step solves

    ``M a_{n+1-alpha_m} + C v_{n+1-alpha_f} + K u_{n+1-alpha_f} = f(t_n + (1-alpha_f) h)``,
    ``u_{n+1} = u_n + h v_n + h^2 ((1/2 - beta) a_n + beta a_{n+1})``,
    ``v_{n+1} = v_n + h ((1 - gamma) a_n + gamma a_{n+1})``

    for ``a_{n+1}`` with the effective matrix
    ``S = (1-alpha_m) M + (1-alpha_f) (gamma h C + beta h^2 K)``, factorised once per h.
    Newmark is ``alpha_m = alpha_f = 0``, HHT ``alpha_m = 0, alpha_f = -alpha``.
    """

    alpha_m = alpha_f = 0.0
    beta, gamma = 0.25, 0.5

    def _build(self, h):
        am, af = self.alpha_m, self.alpha_f
        S = (1 - am) * self.M + ((1 - af) * self.beta * h * h) * self.K
        if self.C is not None:
            S = S + ((1 - af) * self.gamma * h) * self.C
        return _factorize(S)

    def check_step(self, h) -> None:
        """Raise ValueError if ``h`` [s] exceeds :meth:`max_stable_step` (cached per h)."""
        if h in self._ops:
            return
        lim = self.max_stable_step()
        if h > lim:
            label = self.name.replace("_", "-")
            raise ValueError(f"`h` = {h:g} s exceeds the {label} stability limit "
                             f"{lim:g} s (omega_max = {self.omega_max():g} rad/s)")

    def step(self, u, v, a, h, F):
        F = self._load(F)
        self.check_step(h)
        solve = self._operator(h)
        am, af, beta, gamma = self.alpha_m, self.alpha_f, self.beta, self.gamma
        ut = u + h * v + (h * h * (0.5 - beta)) * a        # predictors
        vt = v + (h * (1 - gamma)) * a
        s = 1.0 - af
        rhs = F[0] + sum(F[j] * s ** j for j in range(1, len(F)))
        rhs = rhs - self.K @ ((1 - af) * ut + af * u)
        if am:
            rhs -= am * (self.M @ a)
        if self.C is not None:
            rhs -= self.C @ ((1 - af) * vt + af * v)
        a1 = solve(rhs)
        return ut + (beta * h * h) * a1, vt + (gamma * h) * a1, a1


class Newmark(_AlphaFamily):
    """Newmark's method [1]_; load evaluated at ``t + h``.

    Parameters
    ----------
    beta, gamma : float
        Newmark parameters; the default ``beta = 1/4, gamma = 1/2`` is the average
        acceleration (trapezoidal) rule: second order, unconditionally stable, no
        numerical damping, energy-conserving for undamped linear systems.

    Notes
    -----
    Second order only for ``gamma = 1/2`` (first order otherwise, :attr:`order`
    refers to the default).  Unconditionally stable for ``2 beta >= gamma >= 1/2``;
    otherwise :meth:`step` refuses steps above :meth:`max_stable_step`.
    """

    order = 2
    name = "newmark"

    def __init__(self, M, C, K, *, beta=0.25, gamma=0.5):
        super().__init__(M, C, K)
        self.beta = real("beta", beta, 0.0, rule=">= 0")
        self.gamma = real("gamma", gamma, 0.5, rule=">= 1/2")

    def max_stable_step(self) -> float:
        """``Omega_crit / omega_max`` [s] with ``Omega_crit = (gamma/2 - beta)^(-1/2)``
        ([4]_, ch. 9; it ignores damping, which for ``gamma = 1/2`` leaves the
        limit unchanged and for ``gamma > 1/2`` raises it), ``math.inf`` if
        ``2 beta >= gamma``."""
        if 2 * self.beta >= self.gamma:
            return math.inf
        w = self.omega_max()
        return math.inf if w == 0 else 1.0 / math.sqrt(self.gamma / 2 - self.beta) / w


class CentralDifference(Newmark):
    """Explicit central difference: Newmark ``beta = 0, gamma = 1/2``.

    Second order, conditionally stable: ``h <= 2 / omega_max``.  The damping force is
    taken at ``t + h`` (matrix ``M + h C / 2``, explicit if M and C are diagonal), so
    the limit does not shrink with damping ([4]_, ch. 9; checked numerically); the
    ``(2/omega)(sqrt(1 + zeta^2) - zeta)`` limit belongs to the variant that lags the
    damping force by half a step.  :meth:`step` calls :meth:`check_step`.

    Notes
    -----
    For undamped free vibration the scheme conserves the modified energy
    ``energy(u, v) - (h^2 / 8) a^T M a`` (``M a = -K u``), not :meth:`energy`,
    which oscillates by about ``(omega h)^2 / 4`` relative.
    """

    order = 2
    name = "central_difference"

    def __init__(self, M, C, K):
        super().__init__(M, C, K, beta=0.0, gamma=0.5)


class HHTAlpha(_AlphaFamily):
    """Hilber-Hughes-Taylor alpha method [2]_; load at ``t + (1 + alpha) h``.

    ``M a_{n+1} + (1+alpha)(C v_{n+1} + K u_{n+1}) - alpha (C v_n + K u_n) = f``
    with ``beta = (1 - alpha)^2 / 4``, ``gamma = 1/2 - alpha``: second order,
    unconditionally stable, damping of the high frequencies growing with ``-alpha``.

    Parameters
    ----------
    alpha : float
        In ``[-1/3, 0]``; ``0`` is the average-acceleration rule.
    """

    order = 2
    name = "hht_alpha"

    def __init__(self, M, C, K, *, alpha=-0.05):
        super().__init__(M, C, K)
        self.alpha = real("alpha", alpha, -1 / 3, 0.0, "in [-1/3, 0]")
        self.alpha_m, self.alpha_f = 0.0, -self.alpha
        self.beta, self.gamma = (1 - self.alpha) ** 2 / 4, 0.5 - self.alpha


class GeneralizedAlpha(_AlphaFamily):
    """Chung-Hulbert generalized-alpha method [3]_; load at ``t + (1 - alpha_f) h``.

    ``alpha_m = (2 rho_inf - 1)/(rho_inf + 1)``, ``alpha_f = rho_inf/(rho_inf + 1)``,
    ``gamma = 1/2 - alpha_m + alpha_f``, ``beta = (1 - alpha_m + alpha_f)^2 / 4``:
    second order, unconditionally stable, optimal high-frequency dissipation.

    Parameters
    ----------
    rho_inf : float
        Spectral radius at infinite frequency, in ``[0, 1]``; ``1`` is
        non-dissipative (trapezoidal), ``0`` annihilates the highest modes in one step.

    Notes
    -----
    The carried ``a`` is the algorithmic acceleration, not ``M^{-1}(f - C v - K u)``.
    """

    order = 2
    name = "generalized_alpha"

    def __init__(self, M, C, K, *, rho_inf=0.8):
        super().__init__(M, C, K)
        r = self.rho_inf = real("rho_inf", rho_inf, 0.0, 1.0, "in [0, 1]")
        self.alpha_m, self.alpha_f = (2 * r - 1) / (r + 1), r / (r + 1)
        self.gamma = 0.5 - self.alpha_m + self.alpha_f
        self.beta = 0.25 * (1 - self.alpha_m + self.alpha_f) ** 2


class ExactModal(StructuralIntegrator):
    """Exact stepping of the linear model in modal coordinates.

    With ``K phi_i = omega_i^2 M phi_i``, ``Phi^T M Phi = I`` and a modal damping
    ``Phi^T C Phi = diag(d_i)`` (``d_i = 2 zeta_i omega_i`` [1/s]), each mode obeys
    ``q'' + d q' + omega^2 q = g(t)`` with ``g = Phi^T f`` polynomial in time over the
    step.  Per step size, a batched matrix exponential of the augmented
    ``[q, h q', 1, s, s^2/2]`` system gives, for every mode at once, the free-response
    transition matrix and the responses to the unit loads ``1, s, s^2``; a step then
    costs the load projection, an elementwise update and the back projection.  Exact
    for any h up to round-off (relative ~ eps * omega h), for rigid-body modes
    (``omega = 0``) and under-, critically or over-damped modes alike.

    Parameters
    ----------
    M, C, K : see :class:`StructuralIntegrator`
        ``C`` must be modal (e.g. Rayleigh ``a0 M + a1 K``) or None.
    basis : tuple (omega, Phi) or object with ``omega`` and ``shapes``, optional
        Precomputed mass-normalised modes (e.g. a reduced band): omega (m,) [rad/s],
        Phi (n, m); checked.  Default: all modes by dense ``scipy.linalg.eigh(K, M)``.
    n_modes : int, optional
        Keep only the lowest ``n_modes`` modes.
    cutoff : float, optional
        Keep only the modes with ``omega <= cutoff`` [rad/s].

    Notes
    -----
    With a truncated basis (modal reduction) the state lives in the span of the kept
    modes: :meth:`step` projects ``(u, v)`` on it, and the static response of the
    dropped modes to the load is lost (no static correction).  Use
    :meth:`to_modal`, :meth:`step_modal` and :meth:`from_modal` to keep modal state.
    """

    order = math.inf
    name = "exact"

    def __init__(self, M, C, K, *, basis=None, n_modes=None, cutoff=None):
        super().__init__(M, C, K)
        if basis is None:
            w2, Phi = generalized_eigh(_dense(self.K), _dense(self.M))
            if w2[0] < -1e-8 * max(abs(w2[-1]), 1e-300):
                raise ValueError(f"`K` must be positive semi-definite, got eigenvalue "
                                 f"{w2[0]:g} (rad/s)^2")
            w2[w2 < 1e-12 * max(w2[-1], 0.0)] = 0.0
            omega = np.sqrt(w2)
        else:
            if hasattr(basis, "shapes"):                    # e.g. fem.modal.ModalBasis
                basis = (basis.omega, basis.shapes)
            omega, Phi = (np.asarray(x, dtype=float) for x in basis)
            if omega.ndim != 1 or Phi.shape != (self.n, omega.size) or np.any(omega < 0):
                raise ValueError(f"`basis` must be (omega (m,) >= 0, Phi ({self.n}, m)), "
                                 f"got shapes {omega.shape}, {Phi.shape}")
            err = np.abs(Phi.T @ (self.M @ Phi) - np.eye(omega.size)).max()
            KPhi = np.asarray(self.K @ Phi)
            res = np.abs(KPhi - np.asarray(self.M @ Phi) * omega ** 2).max()
            # residual against the scale of its terms (a backward error):
            # |K| |Phi| and omega^2 |M| |Phi|.  Against |K Phi| alone, exact
            # modes of a fine mesh failed: the lowest modes' K Phi is small
            # beside K's entries (a 1024-element beam's LAPACK modes: 2.9e-8)
            scale = (_max_abs(self.K) + float(omega.max(initial=0.0)) ** 2
                     * _max_abs(self.M)) * float(np.abs(Phi).max(initial=0.0))
            if err > 1e-8 or res > 1e-8 * max(scale, 1e-300):
                raise ValueError(f"`basis` must be mass-normalised modes (Phi^T M Phi = I, "
                                 f"K Phi = M Phi omega^2), got deviations {err:.1e}, {res:.1e}")
        keep = np.ones(omega.size, bool)
        if n_modes is not None:
            if isinstance(n_modes, bool) or not isinstance(n_modes, numbers.Integral) \
                    or not 1 <= n_modes <= omega.size:
                raise ValueError(f"`n_modes` must be an integer in [1, {omega.size}], "
                                 f"got {n_modes!r}")
            keep &= np.argsort(np.argsort(omega)) < n_modes
        if cutoff is not None:
            if real("cutoff", cutoff) <= 0:
                raise ValueError(f"`cutoff` must be > 0 rad/s, got {cutoff!r}")
            keep &= omega <= cutoff
            if not keep.any():
                raise ValueError(f"`cutoff` = {cutoff:g} rad/s keeps no mode (lowest "
                                 f"omega = {omega.min():g} rad/s)")
        self.omega, self.Phi = omega[keep], np.ascontiguousarray(Phi[:, keep])
        MPhi = np.asarray(self.M @ self.Phi)
        self._PhiTM = np.ascontiguousarray(MPhi.T)
        self.damping = np.zeros(self.omega.size)
        if self.C is not None:
            CPhi = np.asarray(self.C @ self.Phi)
            self.damping = np.einsum("ij,ij->j", self.Phi, CPhi)
            res = np.abs(CPhi - MPhi * self.damping).max() / max(np.abs(CPhi).max(), 1e-300)
            if res > 1e-8:
                raise ValueError(
                    "`C` is not modal (the undamped modes do not diagonalise it, as "
                    f"Rayleigh a0 M + a1 K would; relative residual {res:.1e}); use a "
                    "time-stepping scheme such as 'newmark' or 'generalized_alpha'")

    def _build(self, h):
        m = self.omega.size
        A = np.zeros((m, 5, 5))
        A[:, 0, 1] = A[:, 1, 2] = A[:, 2, 3] = A[:, 3, 4] = 1.0
        A[:, 1, 0] = -(self.omega * h) ** 2
        A[:, 1, 1] = -self.damping * h
        from scipy.linalg import expm
        E = expm(A)
        T = np.stack([E[:, 0, 0], h * E[:, 0, 1], E[:, 1, 0] / h, E[:, 1, 1]])
        fact = np.array([1.0, 1.0, 2.0])[:, None]     # s^2 = 2 (s^2 / 2)
        P = np.concatenate([h * h * fact * E[:, 0, 2:].T, h * fact * E[:, 1, 2:].T])
        return T, P

    def modal_load(self, F):
        """Modal load coefficients ``G = F Phi`` (p + 1, m) [N / sqrt(kg)]."""
        return self._load(F) @ self.Phi

    def to_modal(self, u, v):
        """Modal coordinates ``q = Phi^T M u``, ``dq = Phi^T M v`` [sqrt(kg) m(/s)]."""
        return self._PhiTM @ u, self._PhiTM @ v

    def from_modal(self, q, dq):
        """Physical ``u = Phi q`` [m], ``v = Phi dq`` [m/s]."""
        return self.Phi @ q, self.Phi @ dq

    def step_modal(self, q, dq, h, G):
        """Advance modal state ``(q, dq)`` (m,) exactly over ``h`` [s] under the modal
        load ``g(t + s h) = sum_j G[j] s**j``, ``G`` of shape (p + 1, m), p <= 2."""
        T, P = self._operator(h)
        G = np.atleast_2d(G)
        p = G.shape[0]
        if G.ndim != 2 or G.shape[1] != self.omega.size or not 1 <= p <= 3:
            raise ValueError(f"`G` must have shape (p + 1, {self.omega.size}) with p <= 2, "
                             f"got {np.shape(G)}")
        q1 = T[0] * q + T[1] * dq + np.einsum("jm,jm->m", P[:p], G)
        dq1 = T[2] * q + T[3] * dq + np.einsum("jm,jm->m", P[3:3 + p], G)
        return q1, dq1

    def step(self, u, v, a, h, F):
        """See :meth:`StructuralIntegrator.step`; ``a`` is not used, ``a1`` is the
        modal acceleration ``Phi (g(1) - d dq1 - omega^2 q1)``."""
        G = self.modal_load(F)
        q1, dq1 = self.step_modal(*self.to_modal(u, v), h, G)
        ddq1 = G.sum(axis=0) - self.damping * dq1 - self.omega ** 2 * q1
        return self.Phi @ q1, self.Phi @ dq1, self.Phi @ ddq1


STRUCTURAL_INTEGRATORS: dict[str, type[StructuralIntegrator]] = {
    cls.name: cls for cls in (Newmark, HHTAlpha, GeneralizedAlpha, CentralDifference,
                              ExactModal)}


def get_structural_integrator(name) -> type[StructuralIntegrator]:
    """Class registered under ``name`` (a StructuralIntegrator subclass passes through).

    Raises
    ------
    ValueError
        For an unknown name; the message lists the valid ones.
    """
    if isinstance(name, type) and issubclass(name, StructuralIntegrator):
        return name
    try:
        return STRUCTURAL_INTEGRATORS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown structural integrator {name!r}; valid names are "
                         f"{sorted(STRUCTURAL_INTEGRATORS)}") from None
