"""Recursive Newton-Euler inverse dynamics of a planar tree.

The textbook recursion (Featherstone, "Rigid Body Dynamics Algorithms", 2008,
ch. 5, written here in planar world coordinates): a forward pass carries
angular velocity and acceleration and the acceleration of each frame origin
from the ground outwards; a backward pass sums each body's inertial force and
moment into its joint.  It loops over bodies in Python, so it is the reference
that :meth:`multibody.TreeModel.dynamics` (the vectorised projection used by
the integrators) is tested against, not the per-step path.

``inverse_dynamics(tree, q, dq, ddq, g)`` returns ``M(q) ddq + F(q, dq)``;
hence ``F = inverse_dynamics(q, dq, 0, g)`` and column ``j`` of ``M`` is
``inverse_dynamics(q, 0, e_j, None)``.
"""
from __future__ import annotations

import numpy as np

from .tree import TreeModel

__all__ = ["inverse_dynamics", "mass_matrix_rnea", "bias_rnea"]


def _cross(w: float, r: np.ndarray) -> np.ndarray:
    """e_z w x r for a scalar rate w."""
    return np.array([-w * r[1], w * r[0]])


def _rot(theta: float, v) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def inverse_dynamics(tree: TreeModel, q, dq, ddq, gravity=None) -> np.ndarray:
    """Generalised forces that give the accelerations ``ddq``: ``M ddq + F``.

    Parameters
    ----------
    tree : TreeModel
    q, dq, ddq : (n,) arrays
    gravity : (2,) array or None
        [m/s^2].

    Returns
    -------
    (n,) array
    """
    n = tree.n_dof
    g = np.zeros(2) if gravity is None else np.asarray(gravity, float)
    theta = np.zeros(n)
    omega = np.zeros(n)
    alpha = np.zeros(n)
    origin = np.zeros((n, 2))
    acc = np.zeros((n, 2))
    for i, j in enumerate(tree.joints):
        p = j.parent
        th_p, w_p, a_p = (0.0, 0.0, 0.0) if p < 0 else (theta[p], omega[p], alpha[p])
        o_p = np.zeros(2) if p < 0 else origin[p]
        acc_p = np.zeros(2) if p < 0 else acc[p]
        if j.kind == "revolute":
            d = _rot(th_p, j.offset)
            theta[i] = th_p + j.angle + q[i]
            omega[i], alpha[i] = w_p + dq[i], a_p + ddq[i]
            acc[i] = acc_p + _cross(a_p, d) - w_p * w_p * d
        else:
            u = _rot(th_p, j.axis)
            d = _rot(th_p, j.offset) + q[i] * u
            theta[i] = th_p + j.angle
            omega[i], alpha[i] = w_p, a_p
            acc[i] = (acc_p + _cross(a_p, d) - w_p * w_p * d + 2 * _cross(w_p, dq[i] * u)
                      + ddq[i] * u)
        origin[i] = o_p + d
    force = np.zeros((n, 2))     # force through joint i onto body i's subtree
    moment = np.zeros(n)         # moment about origin i
    tau = np.zeros(n)
    for i in range(n - 1, -1, -1):
        b = tree.bodies[i]
        r = _rot(theta[i], b.com)
        a_c = acc[i] + _cross(alpha[i], r) - omega[i] ** 2 * r
        f = b.mass * (a_c - g)
        force[i] += f
        moment[i] += b.inertia * alpha[i] + (r[0] * f[1] - r[1] * f[0])
        j = tree.joints[i]
        if j.kind == "revolute":
            tau[i] = moment[i]
        else:
            p = j.parent
            tau[i] = force[i] @ _rot(0.0 if p < 0 else theta[p], j.axis)
        p = j.parent
        if p >= 0:
            d = origin[i] - origin[p]
            force[p] += force[i]
            moment[p] += moment[i] + (d[0] * force[i][1] - d[1] * force[i][0])
    return tau


def mass_matrix_rnea(tree: TreeModel, q) -> np.ndarray:
    """M(q) column by column from unit accelerations."""
    n = tree.n_dof
    z = np.zeros(n)
    return np.column_stack([inverse_dynamics(tree, q, z, np.eye(n)[k]) for k in range(n)])


def bias_rnea(tree: TreeModel, q, dq, gravity=None) -> np.ndarray:
    """F(q, dq): velocity-product terms minus the generalised gravity force."""
    return inverse_dynamics(tree, q, dq, np.zeros(tree.n_dof), gravity)
