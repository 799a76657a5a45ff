"""Modal analysis of a linear structure: ``K phi = omega^2 M phi``.

Only the band a scene needs is computed and kept: the lowest ``n_modes``
and/or the modes below ``cutoff_hz``.  Small problems (``n_dof <= 400``) use
dense ``scipy.linalg.eigh``; larger ones use ``scipy.sparse.linalg.eigsh``
in shift-invert mode about 0.  Rigid-body modes (a free-free rod or beam)
are known in closed form (``LinearStructure.rigid_body_modes``): the sparse
path solves on their M-orthogonal complement with a pseudo-inverse of ``K``
(the rigid motions are fixed by a few pinned DOFs and projected out), so no
shift has to be guessed, and returns them first with ``omega = 0``.

References
----------
.. [1] R. R. Craig, A. J. Kurdila, *Fundamentals of Structural Dynamics*,
   2nd ed., Wiley, 2006: modal analysis, free-free systems, mode
   truncation and the mode-acceleration (static correction) method.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .checks import count, positive
from .linear_structure import LinearStructure

__all__ = ["ModalBasis", "clear_solved", "modes", "natural_frequencies", "residual_compliance",
           "DENSE_LIMIT"]

#: Largest number of free DOFs solved with a dense eigensolver.
DENSE_LIMIT = 400


@dataclass(frozen=True, eq=False)
class ModalBasis:
    """Mass-normalised modes kept for a structure.

    Attributes
    ----------
    omega : ndarray, shape (m,)
        Angular frequencies [rad/s], ascending; rigid-body modes are exactly 0.
    shapes : ndarray, shape (n_dof, m)
        Mode shapes ``Phi`` with ``Phi^T M Phi = I`` and
        ``Phi^T K Phi = diag(omega^2)``; each is signed so that its entry of
        largest magnitude is positive.
    kept : int
        Number of modes kept (``m``).
    dropped : int
        ``n_dof - kept``: modes of the structure left out.
    cutoff_hz : float or None
        The cutoff used [Hz]: kept modes satisfy ``f < cutoff_hz``.
    n_rigid : int
        Number of kept rigid-body modes (``omega = 0``).
    """

    omega: np.ndarray
    shapes: np.ndarray
    kept: int
    dropped: int
    cutoff_hz: float | None
    n_rigid: int

    @property
    def frequencies_hz(self) -> np.ndarray:
        """Natural frequencies ``omega / (2 pi)`` [Hz]."""
        return self.omega / (2.0 * np.pi)

    @property
    def n_modes(self) -> int:
        """Number of modes kept."""
        return self.kept


def _as_structure(structure) -> LinearStructure:
    if isinstance(structure, LinearStructure):
        return structure
    assemble = getattr(structure, "assemble", None)
    if assemble is None:
        raise TypeError("`structure` must be a LinearStructure or a model with assemble(), "
                        f"got {type(structure).__name__}")
    return assemble()


def _elastic_solver(structure: LinearStructure):
    """``b -> x`` with ``K x = P^T b`` and ``R^T M x = 0`` (``P`` removes the rigid part).

    Without rigid-body modes this is just ``K^{-1} b`` (sparse LU).  With
    them, the rigid motions are fixed by pinning DOFs chosen by pivoted QR of
    ``R^T`` (so ``R`` restricted to them is invertible), the self-equilibrated
    part of ``b`` is solved for, and the rigid part of ``x`` is removed.
    """
    from scipy.linalg import qr
    from scipy.sparse import csc_matrix
    from scipy.sparse.linalg import splu

    k = csc_matrix(structure.stiffness)     # a chain's is dense
    mass = structure.mass
    rigid = structure.rigid_body_modes()
    if rigid.shape[1] == 0:
        return splu(k).solve
    _, _, piv = qr(rigid.T, pivoting=True, mode="economic")
    keep = np.setdiff1d(np.arange(structure.n_dof), piv[:rigid.shape[1]])
    lu = splu(k[keep][:, keep].tocsc())
    m_rigid = np.asarray(mass @ rigid)

    def solve(b):
        b = np.asarray(b, dtype=float)
        b = b - m_rigid @ (rigid.T @ b)
        x = np.zeros(structure.n_dof)
        x[keep] = lu.solve(b[keep])
        return x - rigid @ (m_rigid.T @ x)

    return solve


#: the last few modal decompositions, by a digest of the structure's
#: matrices: a scene is built several times in one command (the run, the
#: error estimate's companion, the accuracy choice's candidates), and the
#: eigen-solve is most of a structure's build (brachiation's 160-DOF cable:
#: 0.3 s each)
_SOLVED: dict = {}
_SOLVED_MAX = 8


def clear_solved() -> None:
    """Forget the modal decompositions kept for the next build: a timed
    command then pays its eigen-solves as a new process would."""
    _SOLVED.clear()


def _digest(*arrays) -> bytes:
    import hashlib
    h = hashlib.blake2b(digest_size=20)
    for a in arrays:
        if hasattr(a, "tocsr"):          # sparse: its structure and values
            a = a.tocsr()
            parts = (a.data, a.indices, a.indptr, np.asarray(a.shape))
        else:
            parts = (np.asarray(a), np.asarray(np.shape(a)))
        for p in parts:
            h.update(np.ascontiguousarray(p).view(np.uint8).tobytes())
    return h.digest()


def _remembered(solve):
    """``solve(s, *args)`` computed once for the same matrices and arguments;
    each call gets its own copies."""
    def wrapper(s, *args):
        key = (solve.__name__, _digest(s.stiffness, s.mass), args)
        if key not in _SOLVED:
            if len(_SOLVED) >= _SOLVED_MAX:
                _SOLVED.pop(next(iter(_SOLVED)))
            _SOLVED[key] = solve(s, *args)
        lam, phi, nr = _SOLVED[key]
        return lam.copy(), phi.copy(), nr
    wrapper.__name__, wrapper.__doc__ = solve.__name__, solve.__doc__
    return wrapper


@_remembered
def _dense_modes(s: LinearStructure):
    from .integrators import _dense, generalized_eigh

    lam, phi = generalized_eigh(_dense(s.stiffness), _dense(s.mass))
    nr = s.rigid_body_modes().shape[1]
    lam[:nr] = 0.0
    return np.maximum(lam, 0.0), phi, nr


@_remembered
def _sparse_modes(s: LinearStructure, k: int):
    """Lowest ``k`` modes (rigid ones included) by shift-invert Lanczos, on
    one BLAS thread (:mod:`fem.blas_threads`: ARPACK's many thin BLAS calls
    wait on a threaded OpenBLAS where the cores are busy)."""
    from .blas_threads import one_blas_thread

    with one_blas_thread():
        return _lanczos(s, k)


def _lanczos(s: LinearStructure, k: int):
    from scipy.linalg import eigh
    from scipy.sparse.linalg import LinearOperator, eigsh

    rigid = s.rigid_body_modes()
    nr = rigid.shape[1]
    n_el = min(k - nr, s.n_dof - nr - 1)
    if n_el <= 0:
        return np.zeros(nr), rigid, nr
    solve = _elastic_solver(s)
    op = LinearOperator((s.n_dof, s.n_dof), matvec=solve, dtype=float)
    # a fixed start vector: ARPACK's default is random, which makes results
    # (and the rare convergence failure) differ from run to run
    start = np.linspace(1.0, 2.0, s.n_dof)
    _, vec = eigsh(s.stiffness, k=n_el, M=s.mass, sigma=0.0, which="LM", OPinv=op, v0=start)
    # Rayleigh-Ritz on the converged subspace: M-orthonormal to round-off.
    lam, z = eigh(vec.T @ (s.stiffness @ vec), vec.T @ (s.mass @ vec))
    phi = np.hstack([rigid, vec @ z])
    return np.concatenate([np.zeros(nr), np.maximum(lam, 0.0)]), phi, nr


def modes(structure, n_modes: int | None = None, cutoff_hz: float | None = None) -> ModalBasis:
    """Natural modes of a structure, lowest first.

    Parameters
    ----------
    structure : LinearStructure or model with ``assemble()``
        The structure (a model is assembled first).
    n_modes : int, optional
        Keep at most the lowest ``n_modes`` modes.
    cutoff_hz : float, optional
        Keep only modes with frequency ``f < cutoff_hz`` [Hz].  Without either
        argument every mode is computed (dense solver).

    Returns
    -------
    ModalBasis
        ``omega`` [rad/s], mass-normalised ``shapes``, ``kept`` and ``dropped``.

    Raises
    ------
    ValueError
        On ``n_modes < 1`` or ``cutoff_hz <= 0``, or a ``cutoff_hz`` at or
        below the lowest natural frequency (no mode would be kept).

    Notes
    -----
    ``n_dof <= DENSE_LIMIT`` (or no limit given): dense ``eigh(K, M)``.
    Otherwise ``eigsh`` in shift-invert mode (``sigma = 0``) with the
    pseudo-inverse solver of ``_elastic_solver``; with only a cutoff, the
    number of modes requested doubles until one lies at or above it.

    The response of the dropped modes to a load at a point can be restored
    statically (mode-acceleration / static correction): see
    :func:`residual_compliance`.

    Examples
    --------
    >>> basis = modes(Beam(1.0, 210e9, 3.33e-9, 7850.0, 4e-4, 20, "pinned", "pinned"),
    ...               cutoff_hz=2000.0)
    >>> basis.frequencies_hz  # doctest: +SKIP
    """
    s = _as_structure(structure)
    if n_modes is not None:
        n_modes = count(n_modes, "n_modes")
    if cutoff_hz is not None:
        cutoff_hz = positive(cutoff_hz, "cutoff_hz", "Hz")
    n = s.n_dof
    want = n if n_modes is None else min(n_modes, n)
    n_rigid = s.rigid_body_modes().shape[1]
    # (`want` is every DOF when only a cutoff is given: it then goes sparse, the
    # count doubling below, unless the structure is small)
    if n <= DENSE_LIMIT or (n_modes is None and cutoff_hz is None) \
            or (n_modes is not None and want >= n - n_rigid - 1):
        lam, phi, nr = _dense_modes(s)
    elif n_modes is not None:
        lam, phi, nr = _sparse_modes(s, want)
    else:
        k = min(16, n)
        while True:
            lam, phi, nr = _sparse_modes(s, k)
            top = math.sqrt(lam[-1]) / (2.0 * np.pi)
            if top >= cutoff_hz or lam.size < k or k >= n - 1:
                break
            k = min(2 * k, n - 1)
        if top < cutoff_hz and lam.size < n:
            lam, phi, nr = _dense_modes(s)
    omega = np.sqrt(lam[:want])
    phi = phi[:, :want]
    if cutoff_hz is not None:
        below = omega / (2.0 * np.pi) < cutoff_hz
        if not below.any():
            raise ValueError(f"`cutoff_hz` keeps no mode: it is {cutoff_hz:.6g} Hz, and the "
                             f"lowest natural frequency is {omega[0] / (2.0 * np.pi):.6g} Hz; "
                             f"give a cutoff above it")
        omega, phi = omega[below], phi[:, below]
    if phi.size:
        big = np.argmax(np.abs(phi), axis=0)
        phi = phi * np.sign(phi[big, np.arange(phi.shape[1])])
    omega = np.ascontiguousarray(omega)
    phi = np.ascontiguousarray(phi)
    omega.setflags(write=False)
    phi.setflags(write=False)
    return ModalBasis(omega=omega, shapes=phi, kept=omega.size, dropped=n - omega.size,
                      cutoff_hz=cutoff_hz, n_rigid=int(min(nr, omega.size)))


def natural_frequencies(structure, k: int) -> np.ndarray:
    """Lowest ``k`` natural frequencies [Hz] (rigid-body modes count, at 0 Hz)."""
    return modes(structure, n_modes=k).frequencies_hz


def residual_compliance(structure, basis: ModalBasis, s) -> float:
    """Static compliance at point ``s`` of the modes a basis dropped [m/N].

    ``c = b^T K^+ b - sum_kept (phi_i . b)^2 / omega_i^2`` over the elastic
    modes, with ``b`` the point operator at ``s``: the static correction
    (mode-acceleration method) a truncated modal model adds so that a slow
    point force ``P`` deflects the point by the full ``c_total P``.  Zero for
    a complete basis; rigid-body modes carry no static compliance.

    Parameters
    ----------
    structure : LinearStructure or model with ``assemble()``
        The structure the basis was computed for.
    basis : ModalBasis
        Kept modes.
    s : float
        Material coordinate of the point.
    """
    st = _as_structure(structure)
    dofs, weights = st.point_operator(s)
    b = np.zeros(st.n_dof)
    np.add.at(b, dofs, weights)
    total = float(b @ _elastic_solver(st)(b))
    elastic = basis.omega > 0.0
    p = basis.shapes[:, elastic].T @ b
    return total - float(np.sum(p * p / basis.omega[elastic] ** 2))
