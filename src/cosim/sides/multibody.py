"""The multibody side as a subsystem: a planar tree stepped by its own integrator.

What the compiled kernel ``cosim.sides._multibody_step`` is handed of the
contact laws and joint effects is in :mod:`cosim.sides.multibody_kernel`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from couplers import PointContact
from multibody import TreeModel

from cosim.errors import SimulationError
from cosim.core.loop_face import LoopFace
from cosim.core.ode import INTEGRATORS, RK4, TimeStepper
from cosim.sides.kernel import compiled_module, retired
from cosim.sides.multibody_kernel import (CompiledFace, SampledSteps, TreeFaceMixin,
                                          kernel_effects, kernel_law)
from cosim.core.subsystem import (DISSIPATED, IMPULSE, MOMENT, QUADRATURES, WORK, EmbeddedContact,
                        StepInput, Subsystem)

if TYPE_CHECKING:
    from multibody import JointEffects

__all__ = ["MultibodySubsystem", "kernel_law"]


#: integrators whose steps the compiled kernel takes (RK4) or feeds (adaptive)
KERNEL_INTEGRATORS = tuple(INTEGRATORS.values())


class MultibodySubsystem(SampledSteps, TreeFaceMixin, CompiledFace, LoopFace, Subsystem):
    """A :class:`multibody.TreeModel` with state ``x = [q, dq]``.

    Parameters
    ----------
    name : str
    model : TreeModel
    q0, dq0 : (n,) arrays
        Initial joint coordinates and velocities.
    ports : dict[str, (int, (2,) sequence)]
        Port name -> (body index, point in the body frame [m]).
    gravity : (2,) array or None
        Gravitational acceleration [m/s^2]; ``None`` builds no gravity term.
    integrator : TimeStepper
        Used by :meth:`step`; RK4 with sub-steps of at most 1e-4 s by default.
    effects : JointEffects or None
        Joint springs, dampers and drives; ``None`` builds none.

    Notes
    -----
    ``aux`` holds, per embedded contact, its :data:`~cosim.core.subsystem.QUADRATURES`
    (impulse, dissipated energy, the step's first moment of the force, work),
    then the energy dissipated by joint dampers and supplied by drives.  The
    integrated state is ``[q, dq, aux, port velocity moments]``, the layout the
    compiled kernel shares (:mod:`cosim.sides._multibody_step`).
    ``peak`` holds each embedded contact's largest penetration, located on
    the integrator's sub-steps (:func:`cosim.core.ode.substep_peaks`).
    """

    #: its compiled kernel's C face mirrors its Python step and outputs (LoopFace)
    loop_face_faithful = True

    capabilities = frozenset({"rigid_impacts", "impact_watch", "connections", "skeleton",
                              "sampled_steps", "compiled_loop"})

    def __init__(self, name: str, model: TreeModel, q0, dq0, ports: dict,
                 gravity=None, integrator: TimeStepper | None = None,
                 effects: JointEffects | None = None):
        super().__init__(name, ports.keys())
        self.model = model
        n = model.n_dof
        self.n_dof = n
        q0, dq0 = np.asarray(q0, float), np.asarray(dq0, float)
        if q0.shape != (n,) or dq0.shape != (n,):
            raise ValueError(f"`q0` and `dq0` of `{name}` must have {n} entries, "
                             f"got {q0.shape} and {dq0.shape}")
        self.x = np.concatenate([q0, dq0])
        self.gravity = None if gravity is None else np.asarray(gravity, float)
        self._g = None if gravity is None else complex(self.gravity[0], self.gravity[1])
        self.integrator = integrator if integrator is not None else RK4(max_step=1e-4)
        self._port_body = np.array([b for b, _ in ports.values()], dtype=int)
        self._port_local = np.array([p for _, p in ports.values()], dtype=float).reshape(-1, 2)
        self._port_local_c = self._port_local[:, 0] + 1j * self._port_local[:, 1]
        self._last_switch = (None, None, None, None)
        self.effects = None if effects is None or effects.empty else effects
        self.aux = np.zeros(2)
        self._embedded: list = []
        #: switches of embedded contacts located during the last step:
        #: (time, embedded slot, now active)
        self.switch_log: list[tuple[float, int, bool]] = []
        #: rigid impacts resolved during the last step (dicts for the summary)
        self.impact_log: list[dict] = []
        #: ``impact_watch(t)``, told of each rigid impact as it is resolved (a
        #: scheme sets it: the guard sees a train that never ends the step)
        self.impact_watch = None
        self._zero_u = np.zeros((self.n_ports, 2))
        self._t0, self._h = 0.0, 1.0
        #: ``int v_p(t) s^j dt`` over the last step, (3, n_ports) complex [m]:
        #: the work of a polynomial port force follows from them exactly
        self.port_moments = np.zeros((3, self.n_ports), complex)

    # ------------------------------------------------------ embedded contacts
    def embed_contact(self, contact: PointContact, port: int, own_side: int,
                      partner_position, partner_velocity=(0.0, 0.0)) -> EmbeddedContact:
        """Evaluate ``contact`` inside this subsystem's integrator against a
        partner port that moves as given (fixed for a rigid reference; set per
        step with :meth:`EmbeddedContact.set_motion` for a moving partner).

        ``own_side`` is +1 when this subsystem is the contact's side ``a``
        (the point), -1 when it is side ``b`` (the surface).  The impulse, the
        dissipated energy and the step's first moment of the force are
        integrated in ``aux``.
        """
        e = EmbeddedContact(contact, port, own_side, partner_position, partner_velocity)
        if e.law.rigid:     # its impacts' module, loaded with the scene, not in the first solve
            import multibody.impact  # noqa: F401
        self._embedded.append(e)
        self.aux = np.zeros(4 * len(self._embedded) + 2)
        self.peak = np.zeros(len(self._embedded))
        self._kernel = retired(self._kernel)
        return e

    #: embedded slot -> cosim.core.connection_modes.EmbeddedConnection (grasp, friction)
    _connections: dict = {}

    def attach_connection(self, slot: int, connection) -> None:
        """Evaluate embedded contact ``slot`` through ``connection`` (a
        :class:`cosim.core.connection_modes.EmbeddedConnection`: its mode's normal and
        tangential forces, friction, and a grasp on the located touch)."""
        self._connections = {**self._connections, int(slot): connection}
        self._kernel = retired(self._kernel)

    def _connection_switch(self, t, j, on, y):
        """A located switch of connection ``j``: grasp on touch.  Returns the
        same state (a copy) when the mode changed, so the integrator
        re-evaluates the right-hand side in the new mode."""
        n = self.n_dof
        q, dq = y[:n], y[n:2 * n]
        x, v, _, _ = self.model.points_c(self.model.frames(q, dq), dq, self._port_body,
                                        self._port_local_c)
        e = self._embedded[j]
        d, dd = e.penetration(t, x[e.port], v[e.port])
        if self._connections[j].on_switch(t, on, x[e.port] - e.partner(t)[0], d, dd):
            return y.copy()
        return None

    def embedded_quadratures(self) -> np.ndarray:
        """(n_embedded, 4): impulse [N s], dissipated energy [J] and work done on
        this subsystem [J] so far, and the current step's first moment of the
        force ``int f (t - t0) dt`` [N s^2], in the order impulse, dissipated,
        moment, work."""
        return self.aux[:-2].reshape(-1, len(QUADRATURES))

    def ledger(self):
        return float(self.aux[-2]), float(self.aux[-1])

    def ledger_rates(self, t, x):
        if self.effects is None:
            return 0.0, 0.0
        n = self.n_dof
        return self.effects.rates(t, x[:n], x[n:2 * n])

    def _joint_forces(self, t, y, F):
        """``F`` less the joint effects' torques, and the ledger rates."""
        if self.effects is None:
            return F, 0.0, 0.0
        n = self.n_dof
        q, dq = y[:n], y[n:2 * n]
        drive = self.effects.drive_torque(t, q, dq)
        diss, sup = self.effects.rates(t, q, dq, drive)
        return F - self.effects.torque(t, q, dq, drive), diss, sup

    def _embedded_state(self, t, x, v):
        """Penetration and rate of each embedded contact at ``t`` from complex
        port positions ``x`` and velocities ``v``."""
        for e in self._embedded:
            d, dd = e.penetration(t, x[e.port], v[e.port])
            yield e, d, dd

    # ----------------------------------------------------------- dynamics
    def _evaluate(self, y):
        n = self.n_dof
        q, dq = y[:n], y[n:2 * n]
        kernel = self._compiled()
        if kernel is not None:       # the tree's part of a right-hand side in Python
            return (dq, *kernel.evaluate(y))
        M, F, x, v, J, _ = self.model.evaluate(q, dq, self._g, self._port_body, self._port_local_c)
        return dq, M, F, x, v, J

    @staticmethod
    def _accelerations(M, F, J, u):
        return np.linalg.solve(M, (J.conj().T @ u).real - F)

    def derivatives(self, t, x, u):
        dq, M, F, _, _, J = self._evaluate(x)
        F = self._joint_forces(t, x, F)[0]
        return np.concatenate([dq, self._accelerations(M, F, J, u[:, 0] + 1j * u[:, 1])])

    def _rhs(self, t, y, inputs):
        n2 = 2 * self.n_dof
        dq, M, F, x, v, J = self._evaluate(y[:n2])
        F, diss, sup = self._joint_forces(t, y, F)
        if inputs is None:
            u = np.zeros(self.n_ports, complex)
        else:
            ur = inputs(t)
            u = ur[:, 0] + 1j * ur[:, 1]
        rates, switch, pd, pv = [], [], [], []
        tau = t - self._t0
        for k, (e, d, dd) in enumerate(self._embedded_state(t, x, v)):
            pd.append(d)
            pv.append(dd)
            if k in self._connections:          # a grasp or friction: cosim.core.connection_modes
                xp, vp = e.partner(t)
                uk, f, p, sw = self._connections[k].evaluate(x[e.port] - xp, v[e.port] - vp,
                                                             d, dd)
                u[e.port] += uk
                rates += [f, p, f * tau, (uk.conjugate() * v[e.port]).real]
                switch.append(sw)
                continue
            f, p, sw = e.law.evaluate(d, dd)
            fn = e.side * f * e.normal
            u[e.port] += fn
            rates += [f, p, f * tau, (fn.conjugate() * v[e.port]).real]
            switch.append(sw)
        self._last_switch = (y, np.array(switch), pd, pv)
        s = tau / self._h
        return np.concatenate([dq, self._accelerations(M, F, J, u), rates, (diss, sup),
                               np.concatenate([v, s * v, (s * s) * v]).view(float)])

    def _switch(self, t, y):
        if self._last_switch[0] is y:        # the RHS was just evaluated at this state
            return self._last_switch[1]
        n = self.n_dof
        q, dq = y[:n], y[n:2 * n]
        x, v, _, _ = self.model.points_c(self.model.frames(q, dq), dq, self._port_body,
                                        self._port_local_c)
        return np.array([self._connections[k].conns.switch(self._connections[k].c, d, dd)
                         if k in self._connections else float(e.law.switch(d, dd))
                         for k, (e, d, dd) in enumerate(self._embedded_state(t, x, v))])

    #: the compiled kernel (cosim.sides._multibody_step.MultibodyStep): None until
    #: first asked for, False where it is not built or not chosen
    _kernel = None
    #: whether the kernel steps this side (see :meth:`_compiled_step`)
    _kernel_steps = False

    def _compiled(self):
        """The compiled kernel of this tree, or None (:mod:`cosim.sides.kernel`)."""
        if self._kernel is None:
            self._kernel = self._build_kernel() or False
        return self._kernel or None

    def _compiled_step(self, inputs):
        """The compiled kernel where it takes this step, or None where the
        reference must: the kernel not built or not chosen, grasp or friction
        connections embedded here, a user's own law, drive or integrator, or
        an input that is not a :class:`StepInput`."""
        kernel = self._compiled()
        if kernel is None or not self._kernel_steps:
            return None
        if inputs is not None and type(inputs) is not StepInput:
            return None
        return kernel

    def _build_kernel(self):
        module = compiled_module("_multibody_step")
        if module is None:
            return None
        laws = [kernel_law(e.law) for e in self._embedded]
        try:
            effects = kernel_effects(self.effects)
        except TypeError:               # a user's own drive: the reference steps
            effects, known = None, False
        else:
            known = True
        self._kernel_steps = (known and not self._connections
                              and type(self.integrator) in KERNEL_INTEGRATORS
                              and all(law is not None for law in laws))
        contacts = ([(e.port, e.side, e.normal, e.offset, *law)
                     for e, law in zip(self._embedded, laws)] if self._kernel_steps else [])
        m = self.model
        return self._with_pairs(module.MultibodyStep(
            m.parent, m.revolute, m._offset, m._axis, m._angle0, m.ancestors, m.mass, m.inertia,
            m._com, m._rot_mass, self._g, self._port_body, self._port_local_c, contacts,
            effects if self._kernel_steps else None))

    @property
    def kernel(self) -> str:
        """``"compiled"`` when the compiled kernel takes this side's steps,
        ``"numpy"`` when the reference does."""
        return "compiled" if self._compiled() is not None and self._kernel_steps else "numpy"

    def _probe(self, t, y):
        """Penetrations and rates of the embedded contacts at ``(t, y)``: those
        the right-hand side just found there, else evaluated."""
        last = self._last_switch
        if last[0] is y:
            return last[2], last[3]
        kernel = self._compiled()
        if kernel is not None and self._kernel_steps:
            return kernel.penetrations(t, y)
        n = self.n_dof
        q, dq = y[:n], y[n:2 * n]
        x, v, _, _ = self.model.points_c(self.model.frames(q, dq), dq, self._port_body,
                                        self._port_local_c)
        states = list(self._embedded_state(t, x, v))
        return [d for _, d, _ in states], [dd for _, _, dd in states]

    def _step_impl(self, t, h, inputs: StepInput | None):
        self._t0, self._h = t, h
        switch = self._switch if self._embedded else None
        self.switch_log = []
        self.impact_log = []
        kernel = self._compiled_step(inputs)
        integ = self.integrator
        if kernel is not None and type(integ) is RK4:
            self.port_moments = kernel.step(t, h, self.x, self.aux, inputs, self._embedded,
                                            integ.max_step, integ.free_step or 0.0,
                                            self._on_switch, self.peak)
            return
        self.aux[MOMENT:-2:len(QUADRATURES)] = 0.0      # first moments are per step
        y0 = np.concatenate([self.x, self.aux, np.zeros(6 * self.n_ports)])
        probe = self._probe if self._embedded else None
        if kernel is not None:           # an adaptive method: compiled right-hand side
            kernel.set_step(t, h, inputs, self._embedded)
            rk = self._tree_rk(kernel)          # our pairs only: a plug-in's takes no `tree`
            y1 = integ.integrate(kernel.rhs, t, y0, t + h,
                                 kernel.switch if self._embedded else None,
                                 self._on_switch, coarse=True, probe=probe, peak=self.peak,
                                 **({} if rk is None else {"tree": rk}))
        else:
            # laws' switch functions are positive where closed, a connection's not: no coarse steps
            y1 = integ.integrate(lambda tt, yy: self._rhs(tt, yy, inputs), t, y0, t + h,
                                 switch, self._on_switch, coarse=not self._connections,
                                 probe=probe, peak=self.peak)
        if np.shape(y1) != y0.shape:     # one comparison a step: an installed plug-in's?
            from cosim.core.plugin_guard import bad_state
            bad_state(integ, y1, y0.shape)
        n2, na = 2 * self.n_dof, self.aux.size
        self.x[:] = y1[:n2]
        self.aux[:] = y1[n2:n2 + na]
        self.port_moments = y1[n2 + na:].view(complex).reshape(3, self.n_ports)
        self._last_switch = (None, None, None, None)

    def _on_switch(self, t, j, on, y):
        self.switch_log.append((t, j, on))
        if j in self._connections:
            return self._connection_switch(t, j, on, y)
        if on and self._embedded[j].law.rigid:
            out = self.rigid_impact(t, y, j)
            if out is not None and self.impact_watch is not None:
                self.impact_watch(t)
            return out
        return None

    #: a rigid contact this close to touching takes part in another's impact [m]
    CLOSED_GAP = 1e-9

    def rigid_impact(self, t: float, y: np.ndarray, slot: int):
        """Resolve the impact that embedded rigid contact ``slot`` starts at
        state ``y``.

        Every rigid contact closed at this instant (gap below
        :attr:`CLOSED_GAP`) takes part.  One contact: Poisson restitution and,
        with ``friction > 0``, Coulomb friction integrated in impulse space;
        several: frictionless Poisson impact, the active impulses decided as a
        linear complementarity problem (``multibody.impact``).  Returns the
        state with the post-impact velocities (``aux`` quadratures updated when
        ``y`` carries them), or None if the point is not approaching.

        Raises
        ------
        SimulationError
            If a contact would stay closed after the impact (restitution 0):
            sustained rigid contact is not modelled; use a penalty law.  Or if
            several contacts with friction strike at once.
        """
        from multibody.impact import frictional_impact, frictionless_impact  # where first needed
        n = self.n_dof
        q, dq = y[:n], y[n:2 * n]
        M, _, x, v, J, _ = self.model.evaluate(q, dq, None, self._port_body,
                                               self._port_local_c)
        states = list(self._embedded_state(t, x, v))
        part = [slot] + [k for k, (e, d, _) in enumerate(states)
                         if k != slot and e.law.rigid and d >= -self.CLOSED_GAP]
        rows = []
        for k in part:
            e = self._embedded[k]
            rows.append((e.side * (e.normal.conjugate() * J[e.port]).real,
                         e.side * ((1j * e.normal).conjugate() * J[e.port]).real))
        jn = np.array([r[0] for r in rows])
        jt = np.array([r[1] for r in rows])
        vn, vt = jn @ dq, jt @ dq
        if vn[0] >= 0.0:
            return None
        laws = [self._embedded[k].law for k in part]
        names = [self._embedded[k].contact.name for k in part]
        if len(part) == 1 and laws[0].friction > 0:
            res = frictional_impact(M, dq, jn[0], jt[0], laws[0].restitution, laws[0].friction)
        elif len(part) > 1 and any(law.friction > 0 for law in laws):
            raise SimulationError(
                f"rigid contacts {names} strike at once at t = {t:.6g} s with friction: only "
                f"frictionless simultaneous impacts are modelled; set their friction to 0 or "
                f"use penalty laws")
        else:
            res = frictionless_impact(M, dq, jn, [law.restitution for law in laws])
        out = y.copy()
        out[n:2 * n] = res.dq_plus
        vn_plus, vt_plus = jn @ res.dq_plus, jt @ res.dq_plus
        total = float(np.sum(res.normal_impulse))
        joints = self.model.joint_names
        for i, k in enumerate(part):
            p_i = float(res.normal_impulse[i])
            if y.size > 2 * n:           # the stepping state carries the quadratures
                share = res.energy_loss * (p_i / total if total else 0.0)
                quad = out[2 * n + len(QUADRATURES) * k:]   # contact k's quadratures
                quad[IMPULSE] += p_i
                quad[DISSIPATED] += share
                quad[MOMENT] += p_i * (t - self._t0)
                quad[WORK] -= share    # the kinetic energy the impact took
            if k != slot:
                self.switch_log.append((t, k, True))
            self.impact_log.append({
                "time": float(t), "contact": names[i],
                "simultaneous_with": [m for m in names if m != names[i]],
                "normal_impulse": p_i,
                "tangential_impulse": float(res.tangential_impulse[i]),
                "compression_impulse": float(res.compression_impulse[i]),
                "normal_velocity": [float(vn[i]), float(vn_plus[i])],
                "tangential_velocity": [float(vt[i]), float(vt_plus[i])],
                "q": dict(zip(joints, map(float, q))),
                "dq_before": dict(zip(joints, map(float, dq))),
                "dq_after": dict(zip(joints, map(float, res.dq_plus))),
                "energy_loss": float(res.energy_loss) * (p_i / total if total else 0.0),
                "slip_history": [[float(a), float(b), m] for a, b, m in res.slip_history],
                "slip_end": res.slip_end})
            # a rigid law's restitution is above 0 (refused at load otherwise), so
            # a rebound of e |vn| follows however slow the approach, and a train
            # of them accumulates (the run guard's chatter rule stops it); only a
            # rebound lost to the others' impulses stays closed
            if p_i > 0 and vn_plus[i] <= 1e-9 * abs(vn[i]):
                raise SimulationError(
                    f"rigid contact `{names[i]}` stays closed after its impact at t = {t:.6g} s "
                    f"(normal velocity {vn_plus[i]:.3g} m/s): sustained rigid contact is not "
                    f"modelled; give it a restitution above 0 or use a penalty law")
        return out

    def outputs(self, t, x):
        kernel = self._compiled()
        if kernel is not None:
            return kernel.outputs(x)
        n = self.n_dof
        q, dq = x[:n], x[n:2 * n]
        xp, vp, _, _ = self.model.points_c(self.model.frames(q, dq), dq, self._port_body,
                                          self._port_local_c)
        return np.stack((xp.real, xp.imag), -1), np.stack((vp.real, vp.imag), -1)

    def energy(self, x=None):
        x = self.x if x is None else x
        n = self.n_dof
        q, dq = x[:n], x[n:2 * n]
        kernel = self._compiled()
        if kernel is not None:
            e = kernel.energy(x)
        else:
            e = self.model.kinetic_energy(q, dq) + self.model.potential_energy(q, self.gravity)
        return e if self.effects is None else e + self.effects.potential(q)

    def port_mobility(self, port, direction):
        _, M, _, _, _, J = self._evaluate(self.x)
        jn = (complex(direction[0], direction[1]).conjugate() * J[port]).real
        return float(jn @ np.linalg.solve(M, jn))

    def skeleton(self, x) -> tuple[np.ndarray, np.ndarray]:
        """The tree drawn as lines, for pictures, at state ``x = [q, dq]``:
        ``(lines, joints)``, complex arrays of world points [m]: a polyline
        broken by NaN (each body's origin joined to its children's origins
        and to its ports), and the joints (the body frames' origins)."""
        n = self.n_dof
        q, dq = x[:n], x[n:2 * n]
        fr = self.model.frames(q, dq)
        origin = fr.origin
        ports = origin[self._port_body] + fr.rot[self._port_body] * self._port_local_c
        gap = complex(np.nan, np.nan)
        pieces = []
        for i, p in enumerate(self.model.parent):
            if p >= 0:
                pieces += [origin[p], origin[i], gap]
        for k, b in enumerate(self._port_body):
            pieces += [origin[b], ports[k], gap]
        return np.array(pieces, complex), origin

    def coordinates(self):
        n = self.n_dof
        return {name: (i, n + i) for i, name in enumerate(self.model.joint_names)}

