"""A plane body reduced to its modes and a static correction per visited
boundary segment.

The kept modes ``Phi`` (rigid-body modes of a free body included, from
:func:`fem.modes`: scipy's ``eigsh`` in shift-invert about 0) carry the
dynamics; the modes dropped answer a load at a boundary point with their
static compliance, which a contact adds in series with its spring (the
mode-acceleration method).  For a point of row ``b`` (its outward normal
displacement ``b @ u``) that compliance is

.. math:: c_r = b^T G_r b, \\qquad
          G_r = E^T \\Big(K^{+} - \\sum_{\\omega_i > 0}
          \\frac{\\phi_i \\phi_i^T}{\\omega_i^2}\\Big) E,

with ``E`` the unit columns of the segment's DOFs and ``K^+`` the inverse of
``K`` on the M-orthogonal complement of the rigid-body modes (the body's
elastic response to a self-equilibrated load).  ``G_r`` is computed for a
segment when a point first visits it (one solve per DOF of the segment:
four for P1, six for P2) and kept, so that a port moving along the
boundary pays milliseconds per new segment instead of a solve per boundary
DOF up front.

References
----------
.. [1] R. R. Craig, A. J. Kurdila, *Fundamentals of Structural Dynamics*,
   2nd ed., Wiley, 2006: mode truncation and the mode-acceleration method.
"""
from __future__ import annotations

import numpy as np

from ..modal import ModalBasis, _elastic_solver

__all__ = ["StaticCorrection", "contact_frequency", "mode_rule", "flamant_growth"]

#: the compliance a point force on a continuum gains per halving of the
#: mesh, times ``E t`` (Flamant: ``2 ln 2 / pi``)
FLAMANT = 2.0 * np.log(2.0) / np.pi


class StaticCorrection:
    """Residual (static) compliance of the modes a basis dropped, per
    boundary segment, computed on first use and kept.

    Parameters
    ----------
    structure : PlaneStructure or LinearStructure
        The assembled body.
    basis : ModalBasis
        Its kept modes.
    """

    def __init__(self, structure, basis: ModalBasis):
        self.structure = structure
        self.basis = basis
        elastic = basis.omega > 0.0
        self._phi = np.asarray(basis.shapes[:, elastic])
        self._inv_w2 = 1.0 / np.asarray(basis.omega[elastic]) ** 2
        self._solve = None
        self._segments: dict = {}
        self.solves = 0

    def _solver(self):
        if self._solve is None:
            self._solve = _elastic_solver(self.structure)
        return self._solve

    def residual(self, load) -> np.ndarray:
        """Static displacement of the dropped modes under ``load`` (free DOFs):
        ``K^+ f - Phi Omega^-2 Phi^T f`` over the elastic modes [m]."""
        f = np.asarray(load, dtype=float)
        self.solves += 1
        return self._solver()(f) - self._phi @ (self._inv_w2 * (self._phi.T @ f))

    def segment(self, dofs) -> np.ndarray:
        """``G_r`` on the DOFs ``dofs`` (a segment's free DOFs), (k, k) [m/N]."""
        key = tuple(int(d) for d in dofs)
        if key not in self._segments:
            n = self.structure.n_dof
            g = np.empty((len(key), len(key)))
            for j, d in enumerate(key):
                e = np.zeros(n)
                e[d] = 1.0
                g[:, j] = self.residual(e)[list(key)]
            self._segments[key] = 0.5 * (g + g.T)
        return self._segments[key]

    def compliance(self, point, direction=None) -> float:
        """Residual compliance ``c_r`` [m/N] at ``point`` (what the
        structure's ``point_operator`` takes: ``(group, s)`` for a plane
        body, or a point of a chain it was given, such as a sliding port's
        loop), along the outward normal there or, on a plane body, along
        the unit ``direction`` (world; a following contact's deformed
        normal).  Anywhere on a segment it is ``w^T G_r w`` with the
        segment's ``G_r``, computed once."""
        if direction is None:
            dofs, w = self.structure.point_operator(point)
        else:
            pt = self.structure.boundary_point(*point)
            dofs, w = pt.dofs, np.asarray(direction, float) @ pt.rows
        return self.row_compliance(dofs, w)

    def row_compliance(self, dofs, w) -> float:
        """``w^T G_r w`` [m/N] for the row ``w`` on the free DOFs ``dofs``
        of one boundary segment (its ``G_r`` computed on first use)."""
        if len(dofs) == 0:
            return 0.0
        order = np.argsort(dofs)
        g = self.segment(np.asarray(dofs)[order])
        w = np.asarray(w)[order]
        return float(w @ g @ w)

    @property
    def visited(self) -> int:
        """Number of segments whose ``G_r`` has been computed."""
        return len(self._segments)


def contact_frequency(stiffness: float, mass: float) -> float:
    """``sqrt(k / m) / (2 pi)`` [Hz]: the frequency of a penalty spring ``k``
    [N/m] carrying the striking mass ``m`` [kg] on a rigid wall."""
    return float(np.sqrt(stiffness / mass) / (2.0 * np.pi))


def mode_rule(top_hz: float, contact_hz: float) -> tuple[str, str]:
    """The pre-flight verdict on a modal basis whose highest kept frequency is
    ``top_hz`` against a contact of frequency ``contact_hz``.

    Returns ``(verdict, why)``: ``"ok"`` at 10 times the contact frequency
    or more (with the static correction, the first impact's peak and
    duration within 5e-4 of all the modes' at 10 times on the clamped strip
    of ``tests/test_plane_truncation.py``, and within 1e-4 where the
    dropped modes also hold under 1e-2 of the contact's compliance:
    :func:`dropped_share_rule`), ``"warn"``
    between 1 and 10 times, ``"refuse"`` for the static correction below 1
    time (it then adds compliance to modes that respond dynamically).
    """
    ratio = top_hz / contact_hz
    if ratio >= 10.0:
        return "ok", f"the kept modes reach {ratio:.3g} x the contact frequency"
    if ratio >= 1.0:
        return "warn", (f"the kept modes reach only {ratio:.3g} x the contact frequency "
                        f"({contact_hz:.6g} Hz); keep modes to 10 x it or more (and, with the "
                        f"static correction, until the dropped modes hold under "
                        f"{DROPPED_SHARE:g} of the contact's compliance)")
    return "refuse", (f"the kept modes stop at {ratio:.3g} x the contact frequency "
                      f"({contact_hz:.6g} Hz): a static correction there adds compliance to "
                      f"modes that respond dynamically; keep modes above the contact "
                      f"frequency (10 x it) or turn the correction off")


#: a static correction whose dropped modes hold more than this share of the
#: contact's compliance (``c_r k``) is warned: what it cannot correct, the
#: dropped modes' ringing at the spring's onset, grows with that share
#: (``tests/test_plane_truncation_rule.py``)
DROPPED_SHARE = 1e-2


def dropped_share_rule(share: float) -> tuple[str, str]:
    """The verdict on a static correction whose dropped modes hold ``share``
    (``c_r k``, the dropped compliance over the spring's) of the contact's
    compliance: ``"ok"`` at :data:`DROPPED_SHARE` or less, else ``"warn"``
    (on the strip of ``tests/test_plane_truncation_rule.py`` the first
    impact's peak is then off by up to 3e-4 at 10 times the contact
    frequency, and within 1e-4 once the share is below it)."""
    if share <= DROPPED_SHARE:
        return "ok", f"the dropped modes hold {share:.2g} of the contact's compliance"
    return "warn", (f"the dropped modes hold {share:.2g} of the contact's compliance (over "
                    f"{DROPPED_SHARE:g}): the static correction takes their static part, not "
                    f"their ringing at the spring's onset, which can move the first impact's "
                    f"peak by a few 1e-4; keep more modes until the share is below "
                    f"{DROPPED_SHARE:g}, or soften the spring")


def flamant_growth(stiffness: float, youngs_modulus: float, thickness: float) -> float:
    """``k x 2 ln 2 / (pi E t)``: the share of a point contact's compliance
    that a halving of the mesh adds (Flamant); above 1e-2 a point contact
    depends on the mesh and should be spread."""
    return float(stiffness * FLAMANT / (youngs_modulus * thickness))
