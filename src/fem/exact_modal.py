"""Exact stepping of a linear structure with modal damping,
:class:`ExactModal`: the default structural integrator where it applies."""
from __future__ import annotations

import math
import numbers

import numpy as np

from .checks import real
from .integrator_base import StructuralIntegrator, _dense, _max_abs, generalized_eigh

__all__ = ["ExactModal"]


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
