"""Planar tree-like multibody systems in joint coordinates.

A tree of ``n`` rigid bodies, each attached to its parent (or to the ground) by
one 1-DOF joint, revolute or prismatic.  Joint ``i`` carries body ``i``; its
parent index is ``-1`` for the ground and smaller than ``i`` otherwise, so the
lists are in topological order.

Kinematics are evaluated for the whole tree at once with the *ancestor matrix*
``A[b, j] = 1`` when joint ``j`` lies on the path from the ground to body
``b``: absolute angles, frame origins and Jacobian columns are prefix sums
along the tree, written as matrix products.  No Python loop runs over bodies,
joints or DOFs per evaluation.

Conventions: angles counter-clockwise positive, a body frame's origin sits on
its joint axis, ``q = 0`` puts each child frame at ``offset`` (rotated by the
fixed ``angle``) in its parent's frame.

The equations of motion read ``M(q) ddq + F(q, dq) = Q`` (Lipinski, eq. 4),
with the mass matrix and the velocity-product term obtained by projecting the
bodies' mass-centre accelerations and angular accelerations on the joint
space (Jourdain's principle): ``M = sum_b m_b Jc_b^T Jc_b + I_b Jw_b^T Jw_b``
and ``F = sum_b m_b Jc_b^T (dJc_b dq) - Q_gravity``.  In the plane the angular
Jacobian is constant, so rotation adds no velocity-product term.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

__all__ = ["Body", "Joint", "TreeModel", "Frames", "PointKinematics", "JOINT_KINDS"]

JOINT_KINDS = ("revolute", "prismatic")


def _vec2(value, name: str) -> tuple[float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be two finite numbers [m], got {value!r}")
    return (float(arr[0]), float(arr[1]))


@dataclass(frozen=True)
class Body:
    """A rigid body in the plane.

    Parameters
    ----------
    name : str
        Unique name within the tree.
    mass : float
        Mass [kg]; zero is allowed for a massless intermediate frame.
    inertia : float
        Moment of inertia about the mass centre [kg m^2].
    com : (2,) sequence of float
        Mass centre in the body frame [m].
    points : dict[str, (2,) sequence]
        Named material points in the body frame [m].
    """

    name: str
    mass: float
    inertia: float
    com: tuple[float, float] = (0.0, 0.0)
    points: dict = field(default_factory=dict)

    def __post_init__(self):
        if not (math.isfinite(self.mass) and self.mass >= 0):
            raise ValueError(f"`mass` of body `{self.name}` must be >= 0 kg, got {self.mass!r}")
        if not (math.isfinite(self.inertia) and self.inertia >= 0):
            raise ValueError(
                f"`inertia` of body `{self.name}` must be >= 0 kg m^2, got {self.inertia!r}")
        object.__setattr__(self, "com", _vec2(self.com, f"{self.name}.com"))
        object.__setattr__(self, "points", {
            str(k): _vec2(v, f"{self.name}.points.{k}") for k, v in dict(self.points).items()})


@dataclass(frozen=True)
class Joint:
    """A 1-DOF joint carrying one body.

    Parameters
    ----------
    name : str
        Unique name; it names the joint coordinate.
    kind : {"revolute", "prismatic"}
    parent : int
        Index of the parent body, ``-1`` for the ground.
    offset : (2,) sequence of float
        Joint position in the parent frame [m].
    axis : (2,) sequence of float
        Sliding direction in the parent frame (prismatic only; normalised).
    angle : float
        Fixed rotation of the child frame relative to the parent frame at
        ``q = 0`` [rad].
    """

    name: str
    kind: str
    parent: int = -1
    offset: tuple[float, float] = (0.0, 0.0)
    axis: tuple[float, float] = (1.0, 0.0)
    angle: float = 0.0

    def __post_init__(self):
        if self.kind not in JOINT_KINDS:
            raise ValueError(
                f"`kind` of joint `{self.name}` must be one of {JOINT_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "offset", _vec2(self.offset, f"{self.name}.offset"))
        ax = np.asarray(_vec2(self.axis, f"{self.name}.axis"))
        norm = float(np.hypot(*ax))
        if norm == 0.0:
            raise ValueError(f"`axis` of joint `{self.name}` must be non-zero, got {self.axis!r}")
        object.__setattr__(self, "axis", (ax[0] / norm, ax[1] / norm))
        if not math.isfinite(self.angle):
            raise ValueError(f"`angle` of joint `{self.name}` must be finite, got {self.angle!r}")


class Frames(NamedTuple):
    """Kinematic state of every body frame (world coordinates)."""

    theta: np.ndarray   # (n,) absolute angles [rad]
    origin: np.ndarray  # (n, 2) frame origins [m]
    axis: np.ndarray    # (n, 2) prismatic directions in the world
    omega: np.ndarray   # (n,) angular velocities [rad/s]
    velocity: np.ndarray  # (n, 2) origin velocities [m/s]
    parent_omega: np.ndarray  # (n,) angular velocity of each joint's parent
    cos: np.ndarray     # (n,) cos(theta)
    sin: np.ndarray     # (n,) sin(theta)


class PointKinematics(NamedTuple):
    """Position, velocity, Jacobian and velocity-product term of points."""

    position: np.ndarray      # (m, 2)
    velocity: np.ndarray      # (m, 2)
    jacobian: np.ndarray      # (m, 2, n): velocity = jacobian @ dq
    accel_bias: np.ndarray    # (m, 2): acceleration at ddq = 0 (dJ/dt dq)


def _perp(v: np.ndarray) -> np.ndarray:
    """Rotate vectors (..., 2) by +90 degrees: e_z x v."""
    out = np.empty_like(v)
    out[..., 0] = -v[..., 1]
    out[..., 1] = v[..., 0]
    return out



def _rotate_cs(c: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.empty(np.broadcast_shapes(np.shape(c) + (2,), v.shape))
    out[..., 0] = c * v[..., 0] - s * v[..., 1]
    out[..., 1] = s * v[..., 0] + c * v[..., 1]
    return out


class TreeModel:
    """An immutable planar tree of bodies and joints.

    Parameters
    ----------
    bodies, joints : sequences of :class:`Body` and :class:`Joint`
        ``joints[i]`` carries ``bodies[i]``; ``joints[i].parent < i``.

    Raises
    ------
    ValueError
        If the lists differ in length, a parent index is out of order, names
        repeat, or the tree has no mass to move.
    """

    def __init__(self, bodies, joints):
        bodies, joints = tuple(bodies), tuple(joints)
        if len(bodies) != len(joints) or not bodies:
            raise ValueError(
                f"a tree needs one joint per body and at least one body, got "
                f"{len(bodies)} bodies and {len(joints)} joints")
        for i, j in enumerate(joints):
            if not -1 <= j.parent < i:
                raise ValueError(
                    f"`parent` of joint `{j.name}` must be -1 (ground) or a body index "
                    f"below {i}, got {j.parent}")
        for label, names in (("body", [b.name for b in bodies]), ("joint", [j.name for j in joints])):
            if len(set(names)) != len(names):
                raise ValueError(f"{label} names must be unique, got {names}")
        self.bodies, self.joints = bodies, joints
        n = len(joints)
        self.n_dof = n
        self.parent = np.array([j.parent for j in joints], dtype=int)
        anc = np.zeros((n, n))
        for b in range(n):
            k = b
            while k >= 0:
                anc[b, k] = 1.0
                k = joints[k].parent
        self.ancestors = anc
        self.revolute = np.array([j.kind == "revolute" for j in joints], dtype=float)
        self.prismatic = 1.0 - self.revolute
        self._offset = np.array([j.offset for j in joints])
        self._axis = np.array([j.axis for j in joints])
        self._angle0 = anc @ np.array([j.angle for j in joints])
        self.mass = np.array([b.mass for b in bodies])
        self.inertia = np.array([b.inertia for b in bodies])
        self._com = np.array([b.com for b in bodies])
        self._com_body = np.arange(n)
        # Angular Jacobian is constant in the plane.
        self._jw = anc * self.revolute[None, :]
        self._rot_mass = self._jw.T @ (self.inertia[:, None] * self._jw)
        self._has_parent = self.parent >= 0
        self._parent_idx = np.where(self._has_parent, self.parent, 0)
        if not np.all(np.linalg.eigvalsh(self.mass_matrix(np.zeros(n))) > 0):
            raise ValueError("the tree's mass matrix is singular: every joint must move some mass")

    # ----------------------------------------------------------------- names
    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def body_index(self, name: str) -> int:
        for i, b in enumerate(self.bodies):
            if b.name == name:
                return i
        raise KeyError(f"no body `{name}`; bodies are {[b.name for b in self.bodies]}")

    # ------------------------------------------------------------ kinematics
    def frames(self, q: np.ndarray, dq: np.ndarray) -> Frames:
        """Angles, origins, velocities of every body frame."""
        anc = self.ancestors
        theta = self._angle0 + anc @ (self.revolute * q)
        c, s = np.cos(theta), np.sin(theta)
        pc = np.where(self._has_parent, c[self._parent_idx], 1.0)
        ps = np.where(self._has_parent, s[self._parent_idx], 0.0)
        local = self._offset + (self.prismatic * q)[:, None] * self._axis
        disp = _rotate_cs(pc, ps, local)
        origin = anc @ disp
        axis = _rotate_cs(pc, ps, self._axis)
        omega = anc @ (self.revolute * dq)
        parent_omega = np.where(self._has_parent, omega[self._parent_idx], 0.0)
        # velocity of origin b = sum over ancestors k of dq_k * column_k(origin_b)
        cols = self._columns(origin, np.arange(self.n_dof), origin, axis)
        velocity = np.einsum("bkx,k->bx", cols, dq)
        return Frames(theta, origin, axis, omega, velocity, parent_omega, c, s)

    def _columns(self, x: np.ndarray, body: np.ndarray, origin: np.ndarray,
                 axis: np.ndarray) -> np.ndarray:
        """Jacobian columns (m, n, 2) of world points ``x`` (m, 2) on bodies ``body``."""
        rel = x[:, None, :] - origin[None, :, :]
        cols = self.revolute[None, :, None] * _perp(rel) + self.prismatic[None, :, None] * axis[None]
        return self.ancestors[body][:, :, None] * cols

    def points(self, frames: Frames, dq: np.ndarray, body: np.ndarray,
               local: np.ndarray) -> PointKinematics:
        """Kinematics of material points ``local`` (m, 2) fixed on ``body`` (m,).

        Returns position, velocity, Jacobian and the velocity-product term of
        the acceleration (Lipinski, eqs. 1-2).
        """
        rel = _rotate_cs(frames.cos[body], frames.sin[body], local)
        x = frames.origin[body] + rel
        cols = self._columns(x, body, frames.origin, frames.axis)     # (m, n, 2)
        v = np.einsum("mkx,k->mx", cols, dq)
        # d/dt of each column times dq_k
        dcol = (self.revolute[None, :, None] * _perp(v[:, None, :] - frames.velocity[None])
                + self.prismatic[None, :, None]
                * (frames.parent_omega[:, None] * _perp(frames.axis))[None])
        dcol *= self.ancestors[body][:, :, None]
        a_bias = np.einsum("mkx,k->mx", dcol, dq)
        return PointKinematics(x, v, np.swapaxes(cols, 1, 2), a_bias)

    # -------------------------------------------------------------- dynamics
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Mass matrix M(q) (n, n) [kg, kg m, kg m^2 by joint kind]."""
        fr = self.frames(q, np.zeros_like(q))
        pk = self.points(fr, np.zeros_like(q), self._com_body, self._com)
        return self._mass_matrix(pk.jacobian)

    def _mass_matrix(self, jc: np.ndarray) -> np.ndarray:
        return np.einsum("bxk,bxl,b->kl", jc, jc, self.mass) + self._rot_mass

    def dynamics(self, q: np.ndarray, dq: np.ndarray, gravity: np.ndarray | None = None,
                 body: np.ndarray | None = None, local: np.ndarray | None = None):
        """Mass matrix and the rest of ``M ddq + F = Q``, and optionally the
        kinematics of extra points in the same pass.

        Parameters
        ----------
        q, dq : (n,) arrays
            Joint coordinates and velocities.
        gravity : (2,) array or None
            Gravitational acceleration [m/s^2]; ``None`` when the scene has none.
        body, local : (m,) int array and (m, 2) array, optional
            Extra material points (ports) to evaluate.

        Returns
        -------
        frames : Frames
        M : (n, n) array
        F : (n,) array
            Velocity-product terms minus the generalised gravity force.
        points : PointKinematics or None
            Kinematics of the extra points.
        """
        fr = self.frames(q, dq)
        nb = self.n_dof
        if body is None:
            pk = self.points(fr, dq, self._com_body, self._com)
            extra = None
        else:
            allpk = self.points(fr, dq, np.concatenate([self._com_body, body]),
                                np.concatenate([self._com, local]))
            pk = PointKinematics(*(a[:nb] for a in allpk))
            extra = PointKinematics(*(a[nb:] for a in allpk))
        jc = pk.jacobian
        M = self._mass_matrix(jc)
        acc = pk.accel_bias if gravity is None else pk.accel_bias - gravity
        F = np.einsum("bxk,bx,b->k", jc, acc, self.mass)
        return fr, M, F, extra

    def kinetic_energy(self, q: np.ndarray, dq: np.ndarray) -> float:
        return 0.5 * float(dq @ self.mass_matrix(q) @ dq)

    def potential_energy(self, q: np.ndarray, gravity: np.ndarray | None) -> float:
        """Gravitational potential energy [J] relative to the world origin."""
        if gravity is None:
            return 0.0
        fr = self.frames(q, np.zeros_like(q))
        com = fr.origin + _rotate_cs(fr.cos, fr.sin, self._com)
        return -float(np.sum(self.mass * (com @ gravity)))
