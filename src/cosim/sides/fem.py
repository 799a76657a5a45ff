"""The structural side as a subsystem: a linear structure in modal coordinates.

The state is the modal coordinates ``(q, dq)`` of the kept modes
(mass-normalised, so the modal equations are ``q'' + d q' + omega^2 q = g``).
A port is a material point: its position and velocity are rows ``R`` of the
mode shapes evaluated there (``w = R q``), and a port force becomes the modal
load ``R^T (f . direction)``, i.e. the consistent nodal load projected on the
modes.  The model-exchange face is diagonal, so the monolithic reference pays
no more than the modes it keeps.

Stepping: while every contact embedded in the structure is open, a step is
made by the structure's integrator on the modal equations: by default exact
in time under the polynomial port load (:class:`fem.ExactModal`), or any
scheme of ``fem.STRUCTURAL_INTEGRATORS`` (Newmark, HHT-alpha,
generalized-alpha, central difference), which on the modal equations
(``M = I``, diagonal ``C`` and ``K``) is the same as on the physical model
restricted to the kept modes.  A step over which an embedded contact is, or
becomes, closed is integrated by RK4 on the modal equations with the contact
force, the switch located inside the sub-step (as for a robot), unless the
structure is undamped, stepped exactly and every embedded contact a linear
spring: then the step is taken in closed form, segment by segment
(:mod:`cosim.sides.fem_closed_form`).  The compiled kernel
``cosim.sides._structure_step`` takes both where it is built; where it does not
(damping, another law), ``cosim.sides._structure_rk`` takes the RK4 (:mod:`fem_rk`).
"""
from __future__ import annotations

import logging
import math

import numpy as np

from cosim.core.loop_face import LoopFace
from cosim.core.ode import RK4
from cosim.sides.fem_closed_form import ClosedFormContacts
from cosim.sides.fem_energy import StructureEnergy
from cosim.sides.fem_ports import StructurePorts
from cosim.sides.fem_rk import ContactRK
from cosim.sides.kernel import compiled_module, retired
from cosim.core.subsystem import EmbeddedContact, StepInput, Subsystem

__all__ = ["StructureSubsystem"]

logger = logging.getLogger(__name__)

#: the interface of ``cosim.sides._structure_step`` this module calls (its
#: ``STEP_API``): 2 since ``StructureStep.step`` raises the host's peaks, 3
#: since each port has its own direction.  A kernel built from older sources
#: is not used (said once), for its step would not match the reference.
STEP_API = 3
_stale_said = False


class StructureSubsystem(StructurePorts, ClosedFormContacts, ContactRK, StructureEnergy,
                         LoopFace, Subsystem):
    """A :class:`fem.LinearStructure` reduced to the modes of ``basis``.

    Parameters
    ----------
    name : str
    structure : fem.LinearStructure
    basis : fem.ModalBasis
        Kept modes (mass-normalised).
    ports : dict[str, float]
        Port name -> material coordinate ``s`` (arc length [m], the mass
        index of a chain, a plane body's ``(group, arc length)``).
    u0, v0 : (n_dof,) arrays, optional
        Initial displacement and velocity of the free DOFs (projected on the
        kept modes).
    gravity : (2,) array or None
        Gravity [m/s^2]; ``None`` builds no weight load.
    contact_step : float
        Largest RK4 sub-step while an embedded contact is closed [s].
    integrator : str
        A name of ``fem.STRUCTURAL_INTEGRATORS``; ``"exact"`` by default.
    integrator_options : dict
        Options of that integrator (``beta``, ``gamma``, ``alpha``, ``rho_inf``).
    """

    #: its compiled kernel's C face mirrors its Python step and outputs (LoopFace)
    loop_face_faithful = True

    capabilities = frozenset({"rigid_impacts", "moving_ports", "modes", "compiled_loop",
                              "compiled_follow"})

    def __init__(self, name, structure, basis, ports: dict, u0=None, v0=None, gravity=None,
                 contact_step: float = 1e-6, integrator: str = "exact",
                 integrator_options=None):
        super().__init__(name, ports.keys())
        from fem import ExactModal

        self.structure, self.basis = structure, basis
        self.omega = np.asarray(basis.omega, float)
        self.Phi = np.asarray(basis.shapes, float)
        m = self.omega.size
        self.n_modes = m
        self._stepper = ExactModal(structure.mass, structure.damping, structure.stiffness,
                                   basis=(self.omega, self.Phi))
        self.modal_damping = np.asarray(self._stepper.damping, float)
        rows, refs = [], []
        for s in ports.values():
            dofs, w = structure.point_operator(s)
            rows.append(w @ self.Phi[dofs])
            refs.append(structure.reference_position(s))
        self._R = np.array(rows).reshape(len(rows), m)
        self.port_coordinates = [s if isinstance(s, tuple) else float(s) for s in ports.values()]
        self._ref = np.array(refs).reshape(-1, 2)
        self._dir = np.asarray(structure.direction, float)
        #: each port's direction (n_ports, 2): its row moves it along this
        #: (the structure's ``direction``, or a plane body's segment normal)
        self._dirs = np.array([self._port_direction(s) for s in ports.values()],
                              float).reshape(-1, 2)
        self._dirc = self._dirs[:, 0] + 1j * self._dirs[:, 1]
        self._g_modal = np.zeros(m)
        if gravity is not None:
            self._g_modal = self.Phi.T @ structure.gravity_load(np.asarray(gravity, float))
        n = structure.n_dof
        u0 = np.zeros(n) if u0 is None else np.asarray(u0, float)
        v0 = np.zeros(n) if v0 is None else np.asarray(v0, float)
        q0, dq0 = self._stepper.to_modal(u0, v0)
        self.x = np.concatenate([q0, dq0])
        self.integrator = integrator
        self._ts = self._ts_checked = None
        if integrator != "exact":
            from cosim.core.plugins import provide
            from fem import STRUCTURAL_INTEGRATORS, get_structural_integrator
            # a plug-in's name, in a process that has not read the scene (a sweep's worker)
            provide(STRUCTURAL_INTEGRATORS, "cosim.integrators", integrator)
            cls = get_structural_integrator(integrator)
            self._ts = cls(np.eye(m), np.diag(self.modal_damping) if np.any(
                self.modal_damping) else None, np.diag(self.omega ** 2),
                **(integrator_options or {}))
            from cosim.core.plugin_guard import origin_of
            if origin_of(cls) is not None:
                self._ts_checked = self._check_step
        self._acc = self._modal_acceleration(self.x, None, 0.0)
        self.aux = np.zeros(2)
        self._embedded = []
        #: per hosted contact, closed (1) or open (0) at the end of the last
        #: step as the closed-form stepping left it; -1 before the first step
        self._closed_end = np.zeros(0, np.int8)
        self._bases: dict = {}
        self._t0, self._h = 0.0, 1.0
        #: ``int v_p(t) s^j dt`` over the last step, (3, n_ports) complex [m]
        self.port_moments = np.zeros((3, self.n_ports), complex)
        self._rk4 = RK4(max_step=contact_step)
        self.switch_log: list[tuple[float, int, bool]] = []
        self.impact_log: list[dict] = []
        self._names = [f"{d}" for d in structure.dof_names]

    def _check_step(self, out, m: int) -> None:
        """Refuse what a plug-in structural integrator's ``step`` returned,
        unless three float arrays of shape ``(m,)``."""
        from cosim.core.plugin_guard import refuse
        ok = isinstance(out, tuple) and len(out) == 3 and all(
            np.shape(x) == (m,) and np.asarray(x).dtype.kind == "f" for x in out)
        if not ok:
            raise refuse(self._ts, "step()", out, f"three arrays (u, v, a) of shape ({m},)")

    def outputs(self, t, x):
        if self._kernel:                # the bits the compiled loop's C face reads
            return self._kernel.outputs(x)
        m = self.n_modes
        w, dw = self._R @ x[:m], self._R @ x[m:2 * m]
        return self._ref + w[:, None] * self._dirs, dw[:, None] * self._dirs

    def _port_direction(self, s) -> np.ndarray:
        """The direction port ``s`` moves along: the structure's
        ``port_direction(s)`` where it has one (a plane body: the outward
        normal of the port's segment), else its ``direction``."""
        own = getattr(self.structure, "port_direction", None)
        return self._dir if own is None else np.asarray(own(s), float)

    def _modal_force(self, u):
        """Modal load of port forces ``u`` (..., n_ports, 2)."""
        return np.einsum("...px,px->...p", u, self._dirs) @ self._R

    def port_mobility(self, port, direction):
        """``n^T J M^-1 J^T n`` within the kept modes: ``(n . dir)^2 |R_p|^2``."""
        c = float(np.asarray(direction, float) @ self._dirs[port])
        return c * c * float(self._R[port] @ self._R[port])

    def port_participation(self, port, direction) -> np.ndarray:
        """``(n . dir) R_p``: how each mass-normalised kept mode moves a port
        along ``direction`` (its squares sum to :meth:`port_mobility`)."""
        c = float(np.asarray(direction, float) @ self._dirs[port])
        return c * np.array(self._R[port], float)

    @property
    def natural_frequencies_hz(self) -> np.ndarray:
        return self.omega / (2 * math.pi)

    def closed_contact_step(self) -> float:
        """``contact_step`` [s]: the RK4 that steps every kept mode while a
        hosted contact is closed takes steps no longer than this."""
        return self._rk4.max_step

    # ----------------------------------------------------------- dynamics
    def derivatives(self, t, x, u):
        m = self.n_modes
        q, dq = x[:m], x[m:2 * m]
        g = self._modal_force(u) + self._g_modal
        return np.concatenate([dq, g - self.modal_damping * dq - self.omega ** 2 * q])

    def coordinates(self):
        return {}

    def compiled_face(self):
        """The compiled model-exchange face (``cosim.sides._modal_face.ModalFace``)
        at the ports' present rows, or None where it is not built or not
        chosen, or where the ports move along different directions; on a
        structure meshed along a line it can move them under a point
        (:meth:`move_port`)."""
        module = compiled_module("_modal_face")
        if module is None or np.any(self._dirs != self._dir):
            return None         # the face takes one direction for every port
        line = self.line_geometry()
        return module.ModalFace(self._R, self._ref, self._dir, self.omega, self.modal_damping,
                                self._g_modal, line)

    def named_values(self, X):
        """Physical DOFs of states ``X`` (..., 2 m): names, u, v."""
        m = self.n_modes
        return self._names, X[..., :m] @ self.Phi.T, X[..., m:2 * m] @ self.Phi.T

    # -------------------------------------------------- embedded contacts
    def embed_contact(self, contact, port, own_side, partner_position,
                      partner_velocity=(0.0, 0.0)):
        """As :meth:`cosim.sides.multibody.MultibodySubsystem.embed_contact`."""
        if contact.law.rigid:
            raise ValueError(f"contact `{contact.name}`: a rigid law on a structure would "
                             f"need an impact law of the continuum; use a penalty law")
        e = EmbeddedContact(contact, port, own_side, partner_position, partner_velocity)
        self._embedded.append(e)
        self.aux = np.zeros(4 * len(self._embedded) + 2)
        self._closed_end = np.full(len(self._embedded), -1, np.int8)
        self._kernel = retired(self._kernel)
        self._closed_ok, self._rk = None, retired(self._rk)
        self.peak = np.zeros(len(self._embedded))
        return e

    def embedded_quadratures(self):
        """As :meth:`cosim.sides.multibody.MultibodySubsystem.embedded_quadratures`."""
        return self.aux[:-2].reshape(-1, 4)

    def _contacts(self, t, q, dq):
        """Each embedded contact with its penetration and rate at ``t``."""
        w, dw = self._R @ q, self._R @ dq
        for e in self._embedded:
            p, dirc = self._ref[e.port], self._dirc[e.port]
            d, dd = e.penetration(t, complex(p[0], p[1]) + w[e.port] * dirc, dw[e.port] * dirc)
            yield e, d, dd

    def _switch(self, t, y):
        m = self.n_modes
        return np.array([float(e.law.switch(d, dd)) for e, d, dd
                         in self._contacts(t, y[:m], y[m:2 * m])])

    def _rhs(self, t, y, inputs):
        m = self.n_modes
        q, dq = y[:m], y[m:2 * m]
        u = np.zeros((self.n_ports, 2)) if inputs is None else inputs(t)
        rates, pd, pv = [], [], []
        tau = t - self._t0
        dirc = self._dirc
        dw = self._R @ dq
        for e, d, dd in self._contacts(t, q, dq):
            pd.append(d)
            pv.append(dd)
            f = float(e.law.force(d, dd))
            fn = e.side * f * e.normal
            u[e.port] += (fn.real, fn.imag)
            rates += [f, float(e.law.dissipation_rate(f, d, dd)), f * tau,
                      (fn.conjugate() * dirc[e.port]).real * dw[e.port]]
        self._last_eval = (y, pd, pv)
        g = self._modal_force(u) + self._g_modal
        ddq = g - self.modal_damping * dq - self.omega ** 2 * q
        v = dw * dirc
        s = tau / self._h
        return np.concatenate([dq, ddq, rates, [float(self.modal_damping @ (dq * dq)), 0.0],
                               np.concatenate([v, s * v, (s * s) * v]).view(float)])

    _last_eval = (None, None, None)

    def _probe(self, t, y):
        """Penetrations and rates of the embedded contacts at ``(t, y)``: those
        the right-hand side just found there, else evaluated."""
        last = self._last_eval
        if last[0] is y:
            return last[1], last[2]
        m = self.n_modes
        states = list(self._contacts(t, y[:m], y[m:2 * m]))
        return [d for _, d, _ in states], [dd for _, _, dd in states]

    # ---------------------------------------------------------- stepping
    def max_stable_step(self) -> float:
        """Largest stable step of the structure's integrator [s] (inf if none)."""
        return math.inf if self._ts is None else float(self._ts.max_stable_step())

    def _modal_acceleration(self, x, inputs, t):
        m = self.n_modes
        u = np.zeros((self.n_ports, 2)) if inputs is None else inputs(t)
        g = self._modal_force(u) + self._g_modal
        return g - self.modal_damping * x[m:2 * m] - self.omega ** 2 * x[:m]

    #: the compiled step (cosim.sides._structure_step.StructureStep), built on the
    #: first step that it covers; False where it does not cover this side
    _kernel = None

    def _compiled_step(self, inputs):
        """The compiled kernel for this step, or None where the reference must
        step: the kernel not built or not chosen (:mod:`cosim.sides.kernel`), a
        structure that is not stepped in closed form (damped, a scheme of
        ``fem.STRUCTURAL_INTEGRATORS``, a hosted contact whose law is not
        linear), or an input that is not a :class:`StepInput`."""
        if self._kernel is False or (inputs is not None and type(inputs) is not StepInput):
            return None
        if self._kernel is None:
            self._kernel = self._build_kernel() or False
        return self._kernel or None

    def compiled_loop_refusal(self) -> str | None:
        """Why the compiled macro loop cannot take this side (words that
        follow its name), or None: its compiled kernel must step it."""
        if self._compiled_step(None) is not None or (self._ts is None and self._rk_built()):
            return None     # the closed form's kernel, or the loop calls the compiled RK4
        return "is not stepped by its compiled kernel"

    def _build_kernel(self):
        free = not self._embedded and self._ts is None and not np.any(self.modal_damping)
        if not (self._closed_form or free):
            return None
        module = compiled_module("_structure_step")
        if module is None:
            return None
        if getattr(module, "STEP_API", 1) != STEP_API:
            global _stale_said
            if not _stale_said:
                _stale_said = True
                logger.warning("the compiled kernel `cosim.sides._structure_step` was built from "
                               "older sources (interface %s, these sources need %s): using "
                               "the numpy reference, which is slower; rebuild it with "
                               "`pip install .`", getattr(module, "STEP_API", 1), STEP_API)
            return None
        contacts = []
        for e in self._embedded:
            contacts.append((e.port, e.side, e.normal, e.offset, e.law.contact_stiffness))
        kernel = module.StructureStep(self.omega, self._R, self._ref, self._dirs, self._g_modal,
                                      contacts, self._active_basis)
        kernel.bound_open = self.bound_open
        return kernel

    @property
    def kernel(self) -> str:
        """``"compiled"`` when the steps run in the compiled kernel, ``"numpy"``
        otherwise."""
        return "compiled" if self._kernel else "numpy"

    def compiled_side(self):
        """The compiled kernel, whose ``side_face()`` is its C face
        (:mod:`cosim.core._side_face`), for a scheme that steps this side from
        compiled code, or None where
        the kernel does not step it exactly with no Python call: a contact
        embedded here, damping, or a scheme of ``fem.STRUCTURAL_INTEGRATORS``.
        The scheme records each such step with :meth:`took_compiled_step`."""
        if self._embedded or self._ts is not None or np.any(self.modal_damping):
            return None
        return self._compiled_step(None)

    #: whether a stalled compiled step was said (see :meth:`_step_impl`)
    _stall_said = False

    def _step_impl(self, t, h, inputs: StepInput | None):
        m = self.n_modes
        self.switch_log = []
        self._t0, self._h = t, h
        kernel = self._compiled_step(inputs)
        if kernel is not None and kernel.set_step(
                t, h, None if inputs is None else inputs.coeffs,
                [(e.t0, e.h, e.motion, e.velocity_coeffs) for e in self._embedded]):
            self.port_moments = pm = np.zeros((3, self.n_ports), complex)
            if not self._embedded:
                kernel.step_free(self.x, pm.view(float))
                return
            saved = self.aux.copy(), self._closed_end.copy(), self.peak.copy()
            try:
                # the peaks array read at each step (embed_contact rebinds it)
                self.switch_log = kernel.step(self.x, self.aux, pm.view(float),
                                              self._closed_end, self.peak)
                return
            except RuntimeError as exc:
                if type(exc).__name__ != "StalledStep":
                    raise
                # a known defect of the compiled step: it can find one switch
                # again and again (three_mass f100 at contact_step 1e-4, t =
                # 0.1112 s); this step is redone by the reference, with the
                # same result: an internal matter, logged once at debug level
                if not self._stall_said:
                    self._stall_said = True
                    logger.debug("subsystem `%s`: %s; this step and any other where it "
                                   "stalls are taken by the numpy reference", self.name, exc)
                self.aux[:], self._closed_end[:], self.peak[:] = saved
                self.switch_log = []
        self.aux[2:-2:4] = 0.0          # first moments are per step
        if self._closed_form:
            self._step_closed_form(t, h, inputs)
            return
        rk = self._rk_step(t, h, inputs)            # a compiled RK4 with the contacts
        closed = self._embedded and (rk.closed(t, self.x) if rk else
                                     bool(np.any(self._switch(t, self.x) > 0)))
        if not closed:
            G = (self._modal_force(inputs.coeffs) if inputs is not None
                 else np.zeros((1, m)))
            G = G.copy()
            G[0] += self._g_modal
            if self._ts is None:
                q1, dq1 = self._stepper.step_modal(self.x[:m], self.x[m:], h, G)
                a1 = None
            else:
                out = self._ts.step(self.x[:m], self.x[m:], self._acc, h, G)
                if self._ts_checked is not None:     # an installed plug-in's: its step
                    self._ts_checked(out, m)
                q1, dq1, a1 = out
            y1 = np.concatenate([q1, dq1])
            if not self._embedded or not (rk.closed(t + h, y1) if rk else
                                          np.any(self._switch(t + h, y1) > 0)):
                self._account_damping(h, self.x, y1)
                self._gauss_moments(h, G, inputs is not None and bool(np.any(inputs.coeffs)))
                self.x[:] = y1
                if a1 is not None:
                    self._acc = a1
                return
        # a contact is or becomes closed: RK4 on the modal equations
        if rk:
            self.port_moments, self.switch_log = rk.step(t, h, self.x, self.aux,
                                                         self._rk4.max_step, self.peak)
        else:
            y0 = np.concatenate([self.x, self.aux, np.zeros(6 * self.n_ports)])
            y1 = self._rk4.integrate(lambda tt, yy: self._rhs(tt, yy, inputs), t, y0, t + h,
                                     self._switch, self._on_switch, probe=self._probe,
                                     peak=self.peak)
            self._last_eval = (None, None, None)
            na = self.aux.size
            self.x[:] = y1[:2 * m]
            self.aux[:] = y1[2 * m:2 * m + na]
            self.port_moments = y1[2 * m + na:].view(complex).reshape(3, self.n_ports)
        if self._ts is not None:
            self._acc = self._modal_acceleration(self.x, inputs, t + h)

    _GAUSS = (np.array([0.5 - math.sqrt(15) / 10, 0.5, 0.5 + math.sqrt(15) / 10]),
              np.array([5.0, 8.0, 5.0]) / 18.0)

    def _gauss_moments(self, h, G, loaded):
        """Port velocity moments of a step without closed contacts, by
        three-point Gauss-Legendre on the exact modal solution (error
        O((omega h)^6)); zero when no port is loaded, for a zero force does
        no work whatever the moments."""
        if not loaded:
            self.port_moments = np.zeros((3, self.n_ports), complex)
            return
        m = self.n_modes
        nodes, weights = self._GAUSS
        dirc = self._dirc
        mom = np.zeros((3, self.n_ports), complex)
        powers = np.arange(G.shape[0])[:, None]
        for sn, w in zip(nodes, weights):
            _, dq = self._stepper.step_modal(self.x[:m], self.x[m:], sn * h, G * sn ** powers)
            v = (self._R @ dq) * dirc
            mom += (w * h) * np.array([v, sn * v, sn * sn * v])
        self.port_moments = mom

    def get_state(self):
        st = super().get_state()
        st.x = np.concatenate([st.x, self._acc, self._closed_end])
        return st

    def set_state(self, state):
        n, m = self.x.size, self.n_modes
        self.t, self.n_steps, self.status = state.t, state.n_steps, state.status
        self.x[...] = state.x[:n]
        self._acc = state.x[n:n + m].copy()
        self._closed_end[:] = state.x[n + m:]
        self.aux[...] = state.aux
        if state.peak is not None:
            self.peak[...] = state.peak

    def _on_switch(self, t, j, on, y):
        self.switch_log.append((t, j, on))

    def _account_damping(self, h, y0, y1):
        """Energy dissipated by Rayleigh damping over an exact step
        (trapezoidal rule on the modal damping power)."""
        if np.any(self.modal_damping):
            m = self.n_modes
            p0 = self.modal_damping @ (y0[m:] ** 2)
            p1 = self.modal_damping @ (y1[m:] ** 2)
            self.aux[-2] += 0.5 * h * float(p0 + p1)
