"""The multibody side as a subsystem: a planar tree stepped by its own integrator."""
from __future__ import annotations

import numpy as np

from couplers import PointContact
from multibody import TreeModel

from .integrators import RK4, TimeStepper
from .subsystem import StepInput, Subsystem

__all__ = ["MultibodySubsystem"]


class MultibodySubsystem(Subsystem):
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
    """

    def __init__(self, name: str, model: TreeModel, q0, dq0, ports: dict,
                 gravity=None, integrator: TimeStepper | None = None):
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
        self.integrator = integrator if integrator is not None else RK4(max_step=1e-4)
        self._port_body = np.array([b for b, _ in ports.values()], dtype=int)
        self._port_local = np.array([p for _, p in ports.values()], dtype=float).reshape(-1, 2)
        self._embedded: list = []
        #: switches of embedded contacts located during the last step:
        #: (time, embedded slot, now active)
        self.switch_log: list[tuple[float, int, bool]] = []
        self._zero_u = np.zeros((self.n_ports, 2))

    # ------------------------------------------------------ embedded contacts
    def embed_contact(self, contact: PointContact, port: int, own_side: int,
                      partner_position, partner_velocity=(0.0, 0.0)) -> None:
        """Evaluate ``contact`` inside this subsystem's integrator against a
        partner port that moves as given (fixed for a rigid reference).

        ``own_side`` is +1 when this subsystem is the contact's side ``a``
        (the point), -1 when it is side ``b`` (the surface).  The impulse and
        dissipated energy of the contact are integrated in ``aux``.
        """
        self._embedded.append((contact, int(port), float(own_side),
                               np.asarray(partner_position, float),
                               np.asarray(partner_velocity, float)))
        self.aux = np.zeros(2 * len(self._embedded))

    def embedded_quadratures(self) -> np.ndarray:
        """(n_embedded, 2): impulse [N s] and dissipated energy [J] so far."""
        return self.aux.reshape(-1, 2)

    def _embedded_state(self, pos, vel):
        out = []
        for contact, port, side, xp, vp in self._embedded:
            n = np.asarray(contact.normal)
            d = contact.offset - side * float((pos[port] - xp) @ n)
            dd = -side * float((vel[port] - vp) @ n)
            out.append((contact, port, side, n, d, dd))
        return out

    # ----------------------------------------------------------- dynamics
    def _kinematics(self, x):
        n = self.n_dof
        q, dq = x[:n], x[n:2 * n]
        _, M, F, pk = self.model.dynamics(q, dq, self.gravity, self._port_body, self._port_local)
        return dq, M, F, pk

    def _accelerations(self, M, F, pk, u):
        Q = np.einsum("mxk,mx->k", pk.jacobian, u)
        return np.linalg.solve(M, Q - F)

    def derivatives(self, t, x, u):
        dq, M, F, pk = self._kinematics(x)
        return np.concatenate([dq, self._accelerations(M, F, pk, u)])

    def _rhs(self, t, y, inputs):
        n2 = 2 * self.n_dof
        dq, M, F, pk = self._kinematics(y[:n2])
        u = self._zero_u.copy() if inputs is None else inputs(t)
        rates = []
        for contact, port, side, n, d, dd in self._embedded_state(pk.position, pk.velocity):
            f = float(contact.law.force(d, dd))
            u[port] += side * f * n
            rates += [f, float(contact.law.dissipation_rate(f, d, dd))]
        return np.concatenate([dq, self._accelerations(M, F, pk, u), rates])

    def _switch(self, t, y):
        n = self.n_dof
        q, dq = y[:n], y[n:2 * n]
        fr = self.model.frames(q, dq)
        pk = self.model.points(fr, dq, self._port_body, self._port_local)
        return np.array([float(c.law.switch(d, dd)) for c, _, _, _, d, dd
                         in self._embedded_state(pk.position, pk.velocity)])

    def _step_impl(self, t, h, inputs: StepInput | None):
        y0 = np.concatenate([self.x, self.aux])
        switch = self._switch if self._embedded else None
        self.switch_log = []
        y1 = self.integrator.integrate(lambda tt, yy: self._rhs(tt, yy, inputs), t, y0, t + h,
                                       switch, lambda ts, j, on: self.switch_log.append(
                                           (ts, j, on)))
        n2 = 2 * self.n_dof
        self.x[:] = y1[:n2]
        self.aux[:] = y1[n2:]

    def outputs(self, t, x):
        n = self.n_dof
        q, dq = x[:n], x[n:2 * n]
        pk = self.model.points(self.model.frames(q, dq), dq, self._port_body, self._port_local)
        return pk.position, pk.velocity

    def energy(self, x=None):
        x = self.x if x is None else x
        n = self.n_dof
        q, dq = x[:n], x[n:2 * n]
        return self.model.kinetic_energy(q, dq) + self.model.potential_energy(q, self.gravity)

    def port_mobility(self, port, direction):
        n = self.n_dof
        q, dq = self.x[:n], self.x[n:]
        _, M, _, pk = self.model.dynamics(q, dq, None, self._port_body[[port]],
                                          self._port_local[[port]])
        jn = np.asarray(direction, float) @ pk.jacobian[0]
        return float(jn @ np.linalg.solve(M, jn))

    def coordinates(self):
        n = self.n_dof
        return {name: (i, n + i) for i, name in enumerate(self.model.joint_names)}
