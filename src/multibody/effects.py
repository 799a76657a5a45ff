"""Joint effects: springs, dampers and drives, only where a scene declares them.

Each effect acts on one joint coordinate.  :class:`JointEffects` gathers them
for a tree and evaluates all of them at once: springs and dampers as vectors
over the joints, drives (few) one by one.  Its energy bookkeeping: springs
store ``1/2 k (q - rest)^2``, dampers dissipate ``c dq^2``, drives supply
``tau dq``.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from .checks import finite, nonnegative

__all__ = ["Table", "MinimumJerk", "Sinusoid", "JointSpring", "JointDamper", "ConstantTorque",
           "TorqueTable", "PDTracking", "JointEffects", "TRAJECTORIES"]


# ------------------------------------------------------------ trajectories
@dataclass(frozen=True)
class Table:
    """Piecewise-linear function of time through ``(times, values)``, held
    constant outside.  Its rate is the slope of the current segment.

    The points are converted once, here, to tuples of floats: a call costs a
    binary search, whatever the table's length (converting them on every
    call made a table of a million points cost 0.2 s a call)."""

    times: tuple
    values: tuple

    def __post_init__(self):
        t = np.array(self.times, float)
        v = np.array(self.values, float)
        if t.ndim != 1 or t.size < 1 or t.shape != v.shape:
            raise ValueError(f"`times` and `values` must be equal-length lists, got "
                             f"{len(self.times)} and {len(self.values)}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ValueError("`times` and `values` must be finite")
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"`times[{i + 1}]` must be greater than the time before it, "
                             f"{float(t[i])!r} (times increase strictly), got "
                             f"{float(t[i + 1])!r}")
        object.__setattr__(self, "times", tuple(t.tolist()))      # Python floats, once
        object.__setattr__(self, "values", tuple(v.tolist()))

    def _segment(self, t) -> int:
        """``i`` with ``times[i] <= t < times[i + 1]`` (a binary search)."""
        return bisect.bisect_right(self.times, t) - 1

    def __call__(self, t):
        ts, vs = self.times, self.values
        if t <= ts[0]:
            return vs[0]
        if t >= ts[-1]:
            return vs[-1]
        i = self._segment(t)
        if t == ts[i]:
            return vs[i]
        # numpy.interp's formula, so that the values are the same to the bit
        return float((vs[i + 1] - vs[i]) / (ts[i + 1] - ts[i]) * (t - ts[i]) + vs[i])

    def rate(self, t):
        ts, vs = self.times, self.values
        if len(ts) < 2 or t <= ts[0] or t >= ts[-1]:
            return 0.0
        i = self._segment(t)
        return (vs[i + 1] - vs[i]) / (ts[i + 1] - ts[i])


@dataclass(frozen=True)
class MinimumJerk:
    """Quintic rest-to-rest motion from ``start`` at ``t_start`` to ``end``
    at ``t_end`` (zero velocity and acceleration at both ends), held outside.
    ``s(x) = 10 x^3 - 15 x^4 + 6 x^5`` (Flash and Hogan 1985)."""

    start: float
    end: float
    t_start: float
    t_end: float

    def __post_init__(self):
        for k in ("start", "end", "t_start", "t_end"):
            finite(getattr(self, k), k)
        if self.t_end <= self.t_start:
            raise ValueError(f"`t_end` must be > `t_start`, got {self.t_end!r} <= "
                             f"{self.t_start!r}")

    def _x(self, t):
        return min(max((t - self.t_start) / (self.t_end - self.t_start), 0.0), 1.0)

    def __call__(self, t):
        x = self._x(t)
        return self.start + (self.end - self.start) * x ** 3 * (10 - 15 * x + 6 * x * x)

    def rate(self, t):
        x = self._x(t)
        return ((self.end - self.start) / (self.t_end - self.t_start)
                * 30 * x * x * (1 - x) ** 2)


@dataclass(frozen=True)
class Sinusoid:
    """``offset + amplitude sin(2 pi frequency t + phase)``."""

    amplitude: float
    frequency: float
    phase: float = 0.0
    offset: float = 0.0

    def __post_init__(self):
        for k in ("amplitude", "frequency", "phase", "offset"):
            finite(getattr(self, k), k)

    def __call__(self, t):
        return self.offset + self.amplitude * math.sin(2 * math.pi * self.frequency * t
                                                       + self.phase)

    def rate(self, t):
        w = 2 * math.pi * self.frequency
        return self.amplitude * w * math.cos(w * t + self.phase)


TRAJECTORIES = {"table": Table, "minimum_jerk": MinimumJerk, "sinusoid": Sinusoid}


# ------------------------------------------------------------------ effects
@dataclass(frozen=True)
class JointSpring:
    """``tau = -stiffness (q - rest)`` [N m/rad or N/m]."""

    joint: int
    stiffness: float
    rest: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "stiffness", nonnegative(self.stiffness, "stiffness", "N m/rad"))
        object.__setattr__(self, "rest", finite(self.rest, "rest"))


@dataclass(frozen=True)
class JointDamper:
    """``tau = -damping dq``."""

    joint: int
    damping: float

    def __post_init__(self):
        object.__setattr__(self, "damping", nonnegative(self.damping, "damping", "N m s/rad"))


@dataclass(frozen=True)
class ConstantTorque:
    """A constant generalised force [N m or N]."""

    joint: int
    torque: float

    def __post_init__(self):
        object.__setattr__(self, "torque", finite(self.torque, "torque"))

    def __call__(self, t, q, dq):
        return self.torque


@dataclass(frozen=True)
class TorqueTable:
    """A generalised force given as a function of time (a :class:`Table`)."""

    joint: int
    torque: Table

    def __call__(self, t, q, dq):
        return self.torque(t)


@dataclass(frozen=True)
class PDTracking:
    """``tau = kp (r(t) - q) + kd (dr/dt - dq)`` tracking a reference ``r``,
    optionally saturated at ``max_torque``."""

    joint: int
    kp: float
    kd: float
    reference: object
    max_torque: float = math.inf

    def __post_init__(self):
        object.__setattr__(self, "kp", nonnegative(self.kp, "kp", "N m/rad"))
        object.__setattr__(self, "kd", nonnegative(self.kd, "kd", "N m s/rad"))
        if not self.max_torque > 0:
            raise ValueError(f"`max_torque` must be > 0, got {self.max_torque!r}")

    def __call__(self, t, q, dq):
        tau = self.kp * (self.reference(t) - q) + self.kd * (self.reference.rate(t) - dq)
        return min(max(tau, -self.max_torque), self.max_torque)


class JointEffects:
    """The joint effects of one tree, evaluated together.

    Parameters
    ----------
    n_dof : int
    effects : iterable of effect objects
    """

    def __init__(self, n_dof: int, effects=()):
        self.n_dof = n_dof
        self.stiffness = np.zeros(n_dof)
        self.rest = np.zeros(n_dof)
        self.damping = np.zeros(n_dof)
        self.drives = []
        for e in effects:
            if not 0 <= e.joint < n_dof:
                raise ValueError(f"effect {type(e).__name__} names joint index {e.joint}, "
                                 f"the tree has {n_dof}")
            if isinstance(e, JointSpring):
                self.stiffness[e.joint] += e.stiffness
                self.rest[e.joint] = e.rest
            elif isinstance(e, JointDamper):
                self.damping[e.joint] += e.damping
            else:
                self.drives.append(e)
        self.has_springs = bool(np.any(self.stiffness))
        self.has_dampers = bool(np.any(self.damping))
        self.empty = not (self.has_springs or self.has_dampers or self.drives)

    def drive_torque(self, t, q, dq) -> np.ndarray:
        tau = np.zeros(self.n_dof)
        for d in self.drives:
            tau[d.joint] += d(t, q[d.joint], dq[d.joint])
        return tau

    def torque(self, t, q, dq, drive=None) -> np.ndarray:
        """Generalised force of every effect at ``(t, q, dq)``."""
        tau = self.drive_torque(t, q, dq) if drive is None else drive.copy()
        if self.has_springs:
            tau -= self.stiffness * (q - self.rest)
        if self.has_dampers:
            tau -= self.damping * dq
        return tau

    def potential(self, q) -> float:
        if not self.has_springs:
            return 0.0
        dq = q - self.rest
        return 0.5 * float(np.sum(self.stiffness * dq * dq))

    def rates(self, t, q, dq, drive=None):
        """Power dissipated by dampers and supplied by drives [W]."""
        diss = float(np.sum(self.damping * dq * dq)) if self.has_dampers else 0.0
        tau = self.drive_torque(t, q, dq) if drive is None else drive
        return diss, float(tau @ dq) if self.drives else 0.0
