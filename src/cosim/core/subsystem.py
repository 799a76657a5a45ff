"""The subsystem protocol: what every side of a co-simulation offers.

A subsystem is a first-order system ``x' = f(t, x, u)``, ``y = g(t, x)``
whose inputs ``u`` are forces on named ports and whose outputs ``y`` are the
positions and velocities of those ports.  It offers both faces of the FMI
standard: model exchange (:meth:`Subsystem.derivatives`,
:meth:`Subsystem.outputs`) for the monolithic reference, and co-simulation
(:meth:`Subsystem.step` with its own integrator, :meth:`Subsystem.get_state`
and :meth:`Subsystem.set_state` for rollback, :meth:`Subsystem.energy`).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import ClassVar, NamedTuple

import numpy as np

from couplers.contact import penetration_c

from cosim.core.hermite import hermite_coefficients
from cosim.core.loop_face import LoopFace

__all__ = ["QUADRATURES", "IMPULSE", "DISSIPATED", "MOMENT", "WORK", "CAPABILITIES", "StepInput", "Subsystem", "RigidReference", "SubsystemState", "EmbeddedContact", "Samples",
           "reparametrised", "hermite_coefficients"]


#: What each contact embedded in a subsystem integrates along the
#: subsystem's state, in this order (its block of ``aux``): the impulse [N s],
#: the energy dissipated [J], the step's first moment of the force
#: ``int f (t - t0) dt`` [N s^2] (restarted every step) and the work the
#: contact did on the subsystem [J].
QUADRATURES = ("impulse", "dissipated", "moment", "work")
IMPULSE, DISSIPATED, MOMENT, WORK = range(len(QUADRATURES))


def reparametrised(coeffs, a: float, b: float) -> np.ndarray:
    """Coefficients in ``sigma`` of the polynomials ``sum_i coeffs[i] s**i``
    (rows lowest first, real or complex) under ``s = a + b sigma``."""
    from math import comb
    coeffs = np.asarray(coeffs)
    p = coeffs.shape[0]
    out = np.zeros(coeffs.shape, dtype=np.result_type(coeffs.dtype, float))
    for i in range(p):
        for k in range(i + 1):
            out[k] += comb(i, k) * a ** (i - k) * b ** k * coeffs[i]
    return out


class StepInput:
    """Port forces over one step, a polynomial in the normalised time.

    ``u(t) = sum_j coeffs[j] * s**j`` with ``s = (t - t0) / h``;
    ``coeffs`` has shape ``(order + 1, n_ports, 2)`` [N].
    """

    __slots__ = ("t0", "h", "coeffs")

    def __init__(self, t0: float, h: float, coeffs: np.ndarray):
        self.t0, self.h, self.coeffs = t0, h, coeffs

    def __call__(self, t: float) -> np.ndarray:
        s = (t - self.t0) / self.h
        c = self.coeffs
        out = c[-1].copy()
        for j in range(len(c) - 2, -1, -1):
            out *= s
            out += c[j]
        return out

    @classmethod
    def zero(cls, t0: float, h: float, n_ports: int) -> "StepInput":
        return cls(t0, h, np.zeros((1, n_ports, 2)))


class Samples(NamedTuple):
    """A side's state at many output points, as its ``sample_steps`` hands
    them to the macro loop (:mod:`cosim.core.schemes.sampled`).

    Attributes
    ----------
    t : (m,) array
        Times [s].
    x : (m, n_states) array
        States.
    quadratures : (m, n_embedded, 4) array
        Each embedded contact's :data:`QUADRATURES` (impulse [N s],
        dissipated [J], first moment [N s^2], work [J]).
    ledger : (m, 2) array
        Energy dissipated inside the side and supplied by drives [J].
    peak : (m, n_embedded) array
        Each embedded contact's largest penetration since the sample before [m].
    energy : (m,) array
        The side's energy [J].
    position, velocity : (m, n_ports, 2) arrays
        Ports' positions [m] and velocities [m/s].
    """

    t: np.ndarray
    x: np.ndarray
    quadratures: np.ndarray
    ledger: np.ndarray
    peak: np.ndarray
    energy: np.ndarray
    position: np.ndarray
    velocity: np.ndarray


class EmbeddedContact:
    """A contact evaluated inside its host subsystem's integrator.

    The partner port moves along a polynomial in the step's normalised time
    ``s = (t - t0) / h``: ``x_p(s) = sum_j motion[j] s**j`` (complex, ``x + iy``
    [m]), set per step by the coupling scheme with :meth:`set_motion`.  A
    rigid partner keeps one constant coefficient.

    Attributes
    ----------
    contact : couplers.PointContact
    port : int
        The host's port.
    side : float
        +1 when the host is the contact's side ``a`` (the point), -1 when it
        is side ``b`` (the surface).
    normal : complex
        Unit normal, from ``b`` towards ``a``.
    """

    __slots__ = ("contact", "law", "port", "side", "normal", "offset", "t0", "h", "motion",
                 "_dmotion", "_still", "_x0")

    def __init__(self, contact, port: int, side: float, partner_position,
                 partner_velocity=(0.0, 0.0)):
        self.contact, self.law = contact, contact.law
        self.port, self.side = int(port), float(side)
        self.normal = complex(contact.normal[0], contact.normal[1])
        self.offset = float(contact.offset)
        xp = complex(partner_position[0], partner_position[1])
        vp = complex(partner_velocity[0], partner_velocity[1])
        self.set_motion(0.0, 1.0, np.array([xp, vp]))

    def set_motion(self, t0: float, h: float, coeffs) -> None:
        """Partner position over ``[t0, t0 + h]``: complex polynomial
        coefficients in ``s`` (lowest first)."""
        c = np.asarray(coeffs, complex)
        self.t0, self.h, self.motion = float(t0), float(h), c
        self._still = not np.any(c[1:])             # a rigid partner: one fixed point
        self._x0 = complex(c[0])
        self._dmotion = (c[1:] * np.arange(1, c.size)) / h if c.size > 1 else np.zeros(1, complex)

    @property
    def velocity_coeffs(self) -> np.ndarray:
        """Partner velocity over the step: the derivative of :attr:`motion` in
        ``t`` [m/s], complex polynomial coefficients in ``s`` (lowest first)."""
        return self._dmotion

    def partner(self, t: float) -> tuple[complex, complex]:
        """Partner port position and velocity at ``t`` (complex)."""
        if self._still:
            return self._x0, 0j
        s = (t - self.t0) / self.h
        x = 0j
        for c in self.motion[::-1]:
            x = x * s + c
        v = 0j
        for c in self._dmotion[::-1]:
            v = v * s + c
        return x, v

    def penetrations(self, t, x, v):
        """:meth:`penetration` at many instants ``t`` (arrays, vectorised)."""
        s = (np.asarray(t, float) - self.t0) / self.h
        xp = np.polyval(self.motion[::-1], s)
        vp = np.polyval(self._dmotion[::-1], s)
        return penetration_c(self.normal, self.offset, self.side * (x - xp),
                             self.side * (v - vp))

    def penetration(self, t: float, x: complex, v: complex) -> tuple[float, float]:
        """Penetration [m] and its rate [m/s] for host port position ``x``
        and velocity ``v`` (complex) at ``t``."""
        xp, vp = self.partner(t)
        return penetration_c(self.normal, self.offset, self.side * (x - xp),
                             self.side * (v - vp))


class SubsystemState:
    """Opaque snapshot for rollback (time, state vector, quadratures, peak
    penetrations since they were last taken, counters)."""

    __slots__ = ("t", "x", "aux", "n_steps", "status", "peak")

    def __init__(self, t, x, aux, n_steps, status, peak=None):
        self.t, self.x, self.aux, self.n_steps, self.status = t, x, aux, n_steps, status
        self.peak = peak


#: The optional faces a side may declare in ``Subsystem.capabilities``, with
#: the members of the class each one promises (checked when the class is
#: made, so a declaration cannot be false):
#:
#: - ``rigid_impacts``: resolves rigid impacts inside its integrator; its
#:   ``impact_log`` lists those of its last step (set in ``__init__``).
#: - ``impact_watch``: its ``impact_watch(t)``, when set, is told of each
#:   rigid impact as the integrator resolves it (set in ``__init__``).
#: - ``connections``: carries embedded grasps or friction (``attach_connection``).
#: - ``moving_ports``: a surface whose ports move to a material coordinate
#:   (``move_port``, ``material_coordinate``, ``surface_tangent``).
#: - ``compiled_follow``: those ports moved in compiled code by the face of
#:   ``follow_face`` (None where there is none), told by ``port_moved``.
#: - ``modes``: a modal structure (``natural_frequencies_hz``, ``named_values``;
#:   ``omega``, ``basis`` and ``structure`` set in ``__init__``).
#: - ``skeleton``: a multibody tree that can draw itself (``skeleton``; ``model``).
#: - ``fmi``: a side made from an FMU (``model_description`` set in ``__init__``).
#: - ``sampled_steps``: takes many macro steps in one call for the macro loop's
#:   sampled path (``sampling_refusal``, ``sample_steps``:
#:   :mod:`cosim.core.schemes.sampled`).
#: - ``compiled_loop``: may be stepped by the compiled macro loop of the
#:   explicit schemes (``compiled_loop_refusal``: :mod:`cosim.core.schemes.driver`).
CAPABILITIES = {
    "rigid_impacts": (),
    "impact_watch": (),
    "connections": ("attach_connection",),
    "moving_ports": ("move_port", "material_coordinate", "surface_tangent"),
    "sliding_ports": ("slide_port",),
    "compiled_follow": ("follow_face", "port_moved"),
    "modes": ("natural_frequencies_hz", "named_values"),
    "skeleton": ("skeleton",),
    "fmi": (),
    "sampled_steps": ("sampling_refusal", "sample_steps"),
    # the compiled macro loop's face of a side (cosim.core.loop_face.LoopFace)
    "compiled_loop": ("compiled_loop_refusal", "compiled_step", "reference_step", "begin_step",
                      "embedded_contacts", "switch_handler", "closed_end"),
}


class Subsystem(ABC):
    """Base class of subsystems, with a template :meth:`~cosim.Subsystem.step`.

    Subclasses set ``n_states``, ``port_names``, the state ``x`` and implement
    :meth:`~cosim.Subsystem._step_impl`, :meth:`derivatives`, :meth:`outputs` and
    :meth:`energy`.  ``aux`` holds quadratures a subsystem integrates along
    its state (the impulse and dissipated energy of contacts embedded in it).
    ``peak`` holds, per embedded contact, its largest penetration [m] (0 if
    none) since :meth:`take_peaks` last read it, located inside the steps by
    the subsystem's integrator.
    """

    #: True for a subsystem without dynamics (wall, ground).
    rigid: bool = False
    #: The optional faces this side has, by name (see ``CAPABILITIES`` in this module);
    #: code that uses a face asks ``"NAME" in sub.capabilities`` instead of
    #: probing for a member.
    capabilities: ClassVar[frozenset] = frozenset()

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        unknown = set(cls.capabilities) - set(CAPABILITIES)
        if unknown:
            raise TypeError(f"{cls.__name__} declares unknown capabilities {sorted(unknown)}; "
                            f"known are {sorted(CAPABILITIES)}")
        missing = [m for c in cls.capabilities for m in CAPABILITIES[c] if not hasattr(cls, m)]
        if missing:
            raise TypeError(f"{cls.__name__} declares capabilities {sorted(cls.capabilities)} "
                            f"but has no {missing}")

    def __init__(self, name: str, port_names):
        self.name = name
        self.port_names = tuple(port_names)
        self.t = 0.0
        self.status = "running"
        self.n_steps = 0
        self.x = np.zeros(0)
        self.aux = np.zeros(0)
        self.peak = np.zeros(0)

    # -------------------------------------------------------------- protocol
    @property
    def n_states(self) -> int:
        return self.x.size

    @property
    def n_ports(self) -> int:
        return len(self.port_names)

    def port_index(self, port: str) -> int:
        try:
            return self.port_names.index(port)
        except ValueError:
            raise KeyError(f"subsystem `{self.name}` has no port `{port}`; "
                           f"ports are {list(self.port_names)}") from None

    def step(self, t: float, h: float, inputs: StepInput | None = None) -> None:
        """Advance the state from ``t`` to ``t + h`` under ``inputs``.

        Raises
        ------
        RuntimeError
            If the subsystem is not running or ``t`` is not its current time.
        """
        if self.status != "running":
            raise RuntimeError(f"subsystem `{self.name}` is {self.status}; it cannot step")
        if not math.isclose(t, self.t, rel_tol=1e-12, abs_tol=1e-15):
            raise RuntimeError(f"subsystem `{self.name}` is at t = {self.t!r} s, asked to step "
                               f"from t = {t!r} s")
        if not (h > 0 and math.isfinite(h)):
            raise ValueError(f"`h` must be > 0 s, got {h!r}")
        try:
            self._step_impl(t, h, inputs)
        except Exception:
            self.status = "failed"
            raise
        self.t = t + h
        self.n_steps += 1

    @abstractmethod
    def _step_impl(self, t: float, h: float, inputs: StepInput | None) -> None:
        """Advance ``self.x`` (and ``self.aux``) over the step."""

    @abstractmethod
    def derivatives(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``dx/dt`` for port forces ``u`` (n_ports, 2) [N]."""

    @abstractmethod
    def outputs(self, t: float, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Port positions and velocities, each (n_ports, 2)."""

    @abstractmethod
    def energy(self, x: np.ndarray | None = None) -> float:
        """Mechanical energy held by the subsystem [J]."""

    def energies(self, X: np.ndarray) -> np.ndarray:
        """:meth:`energy` at each row of the states ``X`` (m, n_states) [J]
        (a side may evaluate them on arrays)."""
        return np.array([self.energy(x) for x in X], dtype=float).reshape(len(X))

    def ledger(self) -> tuple[float, float]:
        """Energy dissipated inside the subsystem and supplied to it by drives
        since the start [J] (co-simulation face)."""
        return 0.0, 0.0

    def ledger_rates(self, t: float, x: np.ndarray) -> tuple[float, float]:
        """Rates of :meth:`ledger` at ``(t, x)`` [W] (model-exchange face)."""
        return 0.0, 0.0

    def port_mobility(self, port: int, direction) -> float:
        """Interface compliance of a port along ``direction`` at the current
        state: the acceleration answering a unit force, ``n^T J M^-1 J^T n``
        [1/kg].  Zero for a rigid subsystem."""
        return 0.0

    def coordinates(self) -> dict[str, tuple[int, int]]:
        """Named coordinates: name -> (index of q in x, index of dq in x)."""
        return {}

    @property
    def host_cpu_time(self) -> float:
        """CPU time [s] spent by a process of the side's own (an FMU's host);
        0 for a side that runs in the run's process."""
        return 0.0

    @property
    def closed_form_contacts(self) -> bool:
        """Whether the side steps its closed contacts in closed form (exactly),
        so that a contact's stiffness sets no integrator step."""
        return False

    def unknown_port_mass(self, port: int) -> str | None:
        """Why the mass behind ``port`` is unknown before the side runs (an
        FMU known from its model description alone), or None."""

    def closed_contact_step(self) -> float | None:
        """The longest step [s] of the RK4 that integrates this side, every
        mode of it, while a contact it hosts is closed (a structure's
        ``contact_step``), or None where no such RK4 steps it."""
        return None

    def compiled_face(self):
        """The compiled model-exchange face that the monolithic reference's
        compiled right-hand side calls (:meth:`derivatives`, :meth:`outputs`
        and :meth:`ledger_rates` in compiled code: an object whose
        ``table()`` gives the ``FaceTable`` declared in
        ``cosim/core/_stacked.pxd``, and ``can_follow``), or None where there
        is none (the Python right-hand side then runs)."""
        return None

    def take_peaks(self) -> np.ndarray:
        """Each embedded contact's largest penetration [m] since the last
        call (0 if it never penetrated), and start again from 0."""
        out = self.peak.copy()
        self.peak[:] = 0.0
        return out

    def took_compiled_step(self, t: float, h: float, port_moments) -> None:
        """Record the step over ``[t, t + h]`` that a scheme took in compiled
        code through the side's ``compiled_side`` (which advanced the state
        and quadratures in place, locating no switch): what :meth:`step`
        records besides them, and the ports' velocity moments."""
        self._t0, self._h = t, h
        self.port_moments = port_moments
        self.switch_log, self.impact_log = [], []
        self.t = t + h
        self.n_steps += 1

    def get_state(self) -> SubsystemState:
        return SubsystemState(self.t, self.x.copy(), self.aux.copy(), self.n_steps, self.status,
                              self.peak.copy())

    def set_state(self, state: SubsystemState) -> None:
        self.t = state.t
        self.x[...] = state.x
        self.aux[...] = state.aux
        self.n_steps = state.n_steps
        self.status = state.status
        if state.peak is not None:
            self.peak[...] = state.peak


class RigidReference(LoopFace, Subsystem):
    """A subsystem without degrees of freedom: a wall or the ground.

    Parameters
    ----------
    name : str
    ports : dict[str, (2,) sequence]
        Fixed port positions [m].
    """

    rigid = True
    capabilities = frozenset({"compiled_loop"})

    def __init__(self, name: str, ports: dict):
        super().__init__(name, ports.keys())
        self._pos = np.array([np.asarray(p, dtype=float) for p in ports.values()]).reshape(-1, 2)
        self._vel = np.zeros_like(self._pos)

    def _step_impl(self, t, h, inputs):
        return None

    def derivatives(self, t, x, u):
        return np.zeros(0)

    def outputs(self, t, x):
        return self._pos, self._vel

    def energy(self, x=None):
        return 0.0

    def energies(self, X):
        """Zero at each row (no per-row call), unless a subclass has an energy."""
        if type(self).energy is RigidReference.energy:
            return np.zeros(len(X))
        return super().energies(X)

    def compiled_loop_refusal(self) -> str | None:
        """Why the compiled macro loop cannot take this side (words that
        follow its name), or None: it holds fixed ports, which a subclass
        may move."""
        return None if type(self) is RigidReference else f"is a rigid {type(self).__name__}"

    def compiled_face(self):
        from cosim.core.kernel_import import import_kernel
        try:
            stacked = import_kernel("cosim.core._stacked")
        except ImportError:             # not built: the Python right-hand side runs
            return None
        return stacked.FixedFace(self._pos)
