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

from .checks import vec2

__all__ = ["Body", "Joint", "TreeModel", "Frames", "PointKinematics", "JOINT_KINDS"]

JOINT_KINDS = ("revolute", "prismatic")


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
        object.__setattr__(self, "com", vec2(self.com, f"{self.name}.com"))
        object.__setattr__(self, "points", {
            str(k): vec2(v, f"{self.name}.points.{k}") for k, v in dict(self.points).items()})


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
        object.__setattr__(self, "offset", vec2(self.offset, f"{self.name}.offset"))
        ax = np.asarray(vec2(self.axis, f"{self.name}.axis"))
        norm = float(np.hypot(*ax))
        if norm == 0.0:
            raise ValueError(f"`axis` of joint `{self.name}` must be non-zero, got {self.axis!r}")
        object.__setattr__(self, "axis", (ax[0] / norm, ax[1] / norm))
        if not math.isfinite(self.angle):
            raise ValueError(f"`angle` of joint `{self.name}` must be finite, got {self.angle!r}")


class Frames(NamedTuple):
    """Kinematic state of every body frame.  Planar vectors are complex
    numbers ``x + iy``: a rotation by ``theta`` is a product with
    ``exp(i theta)`` and ``e_z x v`` is ``1j * v``."""

    theta: np.ndarray     # (n,) absolute angles [rad]
    rot: np.ndarray       # (n,) exp(i theta)
    origin: np.ndarray    # (n,) frame origins [m]
    axis: np.ndarray      # (n,) prismatic directions in the world
    omega: np.ndarray     # (n,) angular velocities [rad/s]
    velocity: np.ndarray  # (n,) origin velocities [m/s]
    parent_omega: np.ndarray  # (n,) angular velocity of each joint's parent


class PointKinematics(NamedTuple):
    """Position, velocity, Jacobian and velocity-product term of points."""

    position: np.ndarray      # (m, 2)
    velocity: np.ndarray      # (m, 2)
    jacobian: np.ndarray      # (m, 2, n): velocity = jacobian @ dq
    accel_bias: np.ndarray    # (m, 2): acceleration at ddq = 0 (dJ/dt dq)


def _complex(v) -> np.ndarray:
    v = np.asarray(v, dtype=float).reshape(-1, 2)
    return v[:, 0] + 1j * v[:, 1]


def _real(z: np.ndarray) -> np.ndarray:
    return np.stack((z.real, z.imag), axis=-1)


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
        self._offset = _complex([j.offset for j in joints])
        self._axis = _complex([j.axis for j in joints])
        self._angle0 = anc @ np.array([j.angle for j in joints])
        self.mass = np.array([b.mass for b in bodies])
        self.inertia = np.array([b.inertia for b in bodies])
        self._com = _complex([b.com for b in bodies])
        self._com_body = np.arange(n)
        # Angular Jacobian is constant in the plane.
        jw = anc * self.revolute[None, :]
        self._rot_mass = jw.T @ (self.inertia[:, None] * jw)
        self._rev1j = 1j * self.revolute
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
        """Angles, origins and velocities of every body frame."""
        anc = self.ancestors
        theta = self._angle0 + anc @ (self.revolute * q)
        rot = np.exp(1j * theta)
        prot = np.append(rot, 1.0)[self.parent]          # parent -1 is the ground
        axis = prot * self._axis
        origin = anc @ (prot * (self._offset + self.prismatic * q * self._axis))
        omega = anc @ (self.revolute * dq)
        parent_omega = np.append(omega, 0.0)[self.parent]
        velocity = self._columns(origin, anc, origin, axis) @ dq
        return Frames(theta, rot, origin, axis, omega, velocity, parent_omega)

    def _columns(self, x, anc_rows, origin, axis):
        """Jacobian columns (m, n) of world points ``x`` (m,) whose ancestor
        rows are ``anc_rows`` (m, n)."""
        return anc_rows * (self._rev1j * (x[:, None] - origin) + self.prismatic * axis)

    def points_c(self, fr: Frames, dq, body, local_c):
        """Kinematics of points ``local_c`` (complex, in their body frames) on
        ``body``, as complex arrays: position, velocity, Jacobian (m, n) and
        the velocity-product term dJ/dt dq (the fast path of :meth:`points`)."""
        anc_rows = self.ancestors[body]
        x = fr.origin[body] + fr.rot[body] * local_c
        cols = self._columns(x, anc_rows, fr.origin, fr.axis)
        v = cols @ dq
        dcol = anc_rows * (self._rev1j * (v[:, None] - fr.velocity)
                           + self.prismatic * 1j * fr.parent_omega * fr.axis)
        return x, v, cols, dcol @ dq

    def points(self, frames: Frames, dq: np.ndarray, body: np.ndarray,
               local: np.ndarray) -> PointKinematics:
        """Kinematics of material points ``local`` (m, 2) fixed on ``body`` (m,).

        Returns position, velocity, Jacobian and the velocity-product term of
        the acceleration (Lipinski, eqs. 1-2), as real arrays.
        """
        x, v, J, a = self.points_c(frames, dq, np.asarray(body, int), _complex(local))
        return PointKinematics(_real(x), _real(v), np.stack((J.real, J.imag), axis=1), _real(a))

    # -------------------------------------------------------------- dynamics
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Mass matrix M(q) (n, n) [kg, kg m, kg m^2 by joint kind]."""
        z = np.zeros_like(q)
        jc = self.points_c(self.frames(q, z), z, self._com_body, self._com)[2]
        return self._mass_matrix(jc)

    def _mass_matrix(self, jc: np.ndarray) -> np.ndarray:
        return ((jc.conj().T * self.mass) @ jc).real + self._rot_mass

    def evaluate(self, q, dq, gravity, body, local_c, fr: Frames | None = None):
        """Fast path for integrators: ``M``, ``F`` and the complex kinematics
        ``(x, v, J)`` of points ``local_c`` (complex, body frames) on ``body``.

        ``gravity`` is a complex number or None.  The generalised force of
        point forces ``u`` (complex, one per point) is ``(J.conj().T @ u).real``.
        """
        fr = self.frames(q, dq) if fr is None else fr
        nb = self.n_dof
        x, v, J, a = self.points_c(fr, dq, np.concatenate((self._com_body, body)),
                                  np.concatenate((self._com, local_c)))
        jc = J[:nb]
        acc = a[:nb] if gravity is None else a[:nb] - gravity
        M = self._mass_matrix(jc)
        F = (jc.conj().T @ (self.mass * acc)).real
        return M, F, x[nb:], v[nb:], J[nb:], a[nb:]

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
        g = None if gravity is None else complex(gravity[0], gravity[1])
        fr = self.frames(q, dq)
        if body is None:
            M, F, *_ = self.evaluate(q, dq, g, np.zeros(0, int), np.zeros(0, complex), fr)
            return fr, M, F, None
        M, F, x, v, J, a = self.evaluate(q, dq, g, np.asarray(body, int), _complex(local), fr)
        return fr, M, F, PointKinematics(_real(x), _real(v), np.stack((J.real, J.imag), 1),
                                         _real(a))

    def kinetic_energy(self, q: np.ndarray, dq: np.ndarray) -> float:
        return 0.5 * float(dq @ self.mass_matrix(q) @ dq)

    def potential_energy(self, q: np.ndarray, gravity: np.ndarray | None) -> float:
        """Gravitational potential energy [J] relative to the world origin."""
        if gravity is None:
            return 0.0
        fr = self.frames(q, np.zeros_like(q))
        com = fr.origin + fr.rot * self._com
        g = complex(gravity[0], gravity[1])
        return -float(np.sum(self.mass * (com.conj() * g).real))
