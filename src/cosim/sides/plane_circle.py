"""A plane body hosting a circle contact (a scene contact with ``radius``):
the circle's penalty spread over the boundary inside it
(:class:`fem.plane.circle.CircleContact` in the kept modes), integrated by
the body inside its own step against the partner's centre moving as the
scheme gives it (:class:`~cosim.core.subsystem.EmbeddedContact`'s motion).

While the circle is clear of the boundary at both ends of a step the body
takes its exact modal step; a step over which it touches is integrated by
RK4 (the body's ``contact_step``) with the circle's force ``-dV/dq`` on the
modes, the touch and release located on the largest penetration.  Over the
step the host accumulates per circle the force on the circle (``-dV/dc``,
through its centre) as a vector: its impulse and first moment in the
step's normalised time, which the scheme turns into the force it hands the
partner (:mod:`cosim.core.circles`), and the work the circle did on the
modes (the embedded work of the contact's ledger).  The stored energy
``V(q, c)`` is the contact's own (:mod:`cosim.core.circles` books it).
"""
from __future__ import annotations

import math

import numpy as np

from cosim.core.subsystem import EmbeddedContact

__all__ = ["CircleHosting", "HostedCircle", "quadrature_parts"]

#: Gauss-Legendre points per part of a boundary segment
GAUSS = 2


def quadrature_parts(structure, radius: float) -> int:
    """Parts each boundary segment is cut into so that the quadrature points
    lie at most ``radius / 40`` apart (two points per part): a contact a
    tenth of the radius wide is then sampled by about four points."""
    ends, _ = structure.boundary_segments(None)
    p = structure.mesh.points
    longest = float(np.max(np.hypot(*(p[ends[:, 1]] - p[ends[:, 0]]).T)))
    return max(1, math.ceil(20.0 * longest / radius - 1e-9))


class HostedCircle(EmbeddedContact):
    """A circle contact embedded in a plane body: the partner's port is the
    circle's centre.  ``circle`` is the modal :class:`CircleContact`;
    ``quad`` the step's ``[int F dt, int F s dt]`` on the circle (x, y
    each) [N s]."""

    __slots__ = ("circle", "quad", "_seg", "_reach", "_amp", "_n_g")

    def __init__(self, contact, port, side, partner_position, partner_velocity, circle):
        super().__init__(contact, port, side, partner_position, partner_velocity)
        self.circle = circle
        self.quad = np.zeros(4)
        # culling (exact): a point x = X + u lies inside the circle only if
        # |X - c| < R + |u|, and |u| <= amp . |q| (amp: each mode's largest
        # displacement at a point); the points of a segment lie within its
        # reach of their centroid
        n_seg = int(circle.segment[-1]) + 1
        self._n_g = circle.weights.size // n_seg
        pts = circle.points.reshape(n_seg, self._n_g, 2)
        self._seg = pts.mean(axis=1)
        self._reach = np.max(np.hypot(*(pts - self._seg[:, None, :]).transpose(2, 0, 1)),
                             axis=1)
        b = np.asarray(circle.trace).reshape(-1, 2, circle.n_coordinates)
        self._amp = np.max(np.hypot(b[:, 0, :], b[:, 1, :]), axis=0)

    def centre(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The centre's position and velocity at ``t`` [m, m/s]."""
        x, v = self.partner(t)
        return np.array([x.real, x.imag]), np.array([v.real, v.imag])

    def row(self, t: float, q, dq) -> tuple[float, float]:
        """The largest penetration ``max_q (R - |x_q - c|)`` [m] and its rate
        at that point [m/s]; where no point can reach the circle, a negative
        bound of it and 0."""
        c, vc = self.centre(t)
        return self._row(q, dq, c, vc, self._near(q, c))[:2]

    def _near(self, q, c):
        """The quadrature points that may lie within ``2 R`` of the centre
        (every point inside the circle among them), or, when there are none,
        a bound of the penetration (at most ``-R``: a touch is always
        located on exact values)."""
        dist = np.hypot(*(self._seg - c).T) - self._reach
        slack = self.circle.radius + float(self._amp @ np.abs(q))
        seg = np.flatnonzero(dist < slack + self.circle.radius)
        if seg.size == 0:
            return float(slack - dist.min())
        return (seg[:, None] * self._n_g + np.arange(self._n_g)).ravel()

    def row_at(self, q, dq, c, vc) -> tuple[float, float]:
        """:meth:`row` for the centre ``c`` moving at ``vc``, over every point."""
        return self._row(q, dq, c, vc, None)[:2]

    def _row(self, q, dq, c, vc, idx):
        """Row, rate, ``x_q - c``, ``|x_q - c|``, the trace's rows and ``idx``
        at the points ``idx`` (all when None); ``idx`` a float (no point
        near): that bound as the row, its rate 0 and nothing else."""
        if isinstance(idx, float):
            return idx, 0.0, None, None
        cc = self.circle
        if idx is None:
            x, b = cc.positions(q), cc.trace
        else:
            b = cc.trace.reshape(-1, 2, cc.n_coordinates)[idx].reshape(-1, cc.n_coordinates)
            x = cc.points[idx] + (b @ q).reshape(-1, 2)
        d = x - c
        r = np.hypot(d[:, 0], d[:, 1])
        j = int(np.argmin(r))
        v = b[2 * j:2 * j + 2] @ dq - vc
        rate = float(-(d[j] @ v) / r[j]) if r[j] > 0 else 0.0
        return float(cc.radius - r[j]), rate, d, r, b, idx

    def load(self, t: float, q, dq):
        """The row (largest penetration, its rate), the load ``-dV/dq`` on the
        coordinates and the force on the circle ``-dV/dc`` at ``t``: as
        :meth:`CircleContact.evaluate`, the positions found once."""
        cc = self.circle
        c, vc = self.centre(t)
        out = self._row(q, dq, c, vc, self._near(q, c))
        if out[0] <= 0.0:
            return out[0], out[1], np.zeros(q.size), np.zeros(2)
        _, _, d, r, b, idx = out
        g = cc.radius - r
        on = np.flatnonzero(g > 0.0)
        w = cc.weights[idx[on]]
        kg = (cc.stiffness * g[on] * w / r[on])[:, None] * d[on]   # [N] along n
        f_q = b.reshape(-1, 2, cc.n_coordinates)[on].reshape(-1, cc.n_coordinates).T @ kg.ravel()
        return out[0], out[1], f_q, -kg.sum(axis=0)


class CircleHosting:
    """The methods a plane body takes to host circle contacts (mixed into
    :class:`~cosim.sides.plane.PlaneSubsystem`)."""

    #: contact name -> (radius [m], stiffness [Pa/m]) of the circles to host
    circle_specs: dict = {}

    def add_circle(self, name: str, radius: float, stiffness: float) -> None:
        """Host contact ``name`` as a circle of ``radius`` [m] whose penalty
        is ``stiffness`` [Pa/m] (before the coupled system embeds it)."""
        self.circle_specs = {**self.circle_specs, name: (float(radius), float(stiffness))}

    @property
    def circles(self) -> list:
        return [e for e in getattr(self, "_embedded", ()) if isinstance(e, HostedCircle)]

    def embed_contact(self, contact, port, own_side, partner_position,
                      partner_velocity=(0.0, 0.0)):
        spec = self.circle_specs.get(contact.name)
        if spec is None:
            return super().embed_contact(contact, port, own_side, partner_position,
                                         partner_velocity)
        from fem.plane.circle import CircleContact
        radius, k = spec
        cc = CircleContact(self.structure, radius, k, basis=self.Phi, gauss=GAUSS,
                           parts=quadrature_parts(self.structure, radius))
        e = HostedCircle(contact, port, own_side, partner_position, partner_velocity, cc)
        self._embedded.append(e)
        self.aux = np.zeros(4 * len(self._embedded) + 2)
        self._closed_end = np.full(len(self._embedded), -1, np.int8)
        self._kernel = False            # the numpy reference steps a circle's host
        self._closed_ok = False
        self.peak = np.zeros(len(self._embedded))
        return e

    def compiled_loop_refusal(self) -> str | None:
        if self.circles:
            return (f"hosts a circle contact (`{self.circles[0].contact.name}`), which its "
                    f"numpy step integrates")
        return super().compiled_loop_refusal()

    def compiled_side(self):
        return None if self.circles else super().compiled_side()

    @property
    def _closed_form(self) -> bool:
        """No closed-form stepping with a circle: its force is not a spring's
        on one port."""
        return False if self.circles else super()._closed_form

    def circle_energy(self, e: HostedCircle, centre) -> tuple[float, np.ndarray]:
        """``V(q, c)`` [J] and the force on the circle [N] at the body's state."""
        energy, _, on_circle = e.circle.evaluate(self.x[:self.n_modes], centre)
        return energy, on_circle

    # ------------------------------------------------------------ stepping
    def _contacts(self, t, q, dq, loads=False):
        """Each embedded contact with its penetration and rate at ``t`` (a
        circle's largest; with ``loads``, a circle's is the tuple of
        :meth:`HostedCircle.load` and its rate None)."""
        if not self.circles:
            yield from super()._contacts(t, q, dq)
            return
        plain = [e for e in self._embedded if not isinstance(e, HostedCircle)]
        rest = iter(()) if not plain else self._plain_contacts(t, q, dq)
        for e in self._embedded:
            if isinstance(e, HostedCircle):
                yield (e, e.load(t, q, dq), None) if loads else (e, *e.row(t, q, dq))
            else:
                yield next(rest)

    def _plain_contacts(self, t, q, dq):
        w, dw = self._R @ q, self._R @ dq
        dirc = complex(self._dir[0], self._dir[1])
        for e in self._embedded:
            if isinstance(e, HostedCircle):
                continue
            p = self._ref[e.port]
            d, dd = e.penetration(t, complex(p[0], p[1]) + w[e.port] * dirc, dw[e.port] * dirc)
            yield e, d, dd

    def _rhs(self, t, y, inputs):
        circles = self.circles
        if not circles:
            return super()._rhs(t, y, inputs)
        m = self.n_modes
        q, dq = y[:m], y[m:2 * m]
        u = np.zeros((self.n_ports, 2)) if inputs is None else inputs(t)
        rates, pd, pv, quads = [], [], [], []
        tau = t - self._t0
        s = tau / self._h
        dirc = complex(self._dir[0], self._dir[1])
        dw = self._R @ dq
        load = np.zeros(m)
        for e, d, dd in self._contacts(t, q, dq, loads=True):
            if isinstance(e, HostedCircle):
                d, dd, f_q, f_c = d
                pd.append(d)
                pv.append(dd)
                load += f_q
                fn = float(np.hypot(*f_c))
                rates += [fn, 0.0, fn * tau, float(f_q @ dq)]
                quads += [f_c[0], f_c[1], s * f_c[0], s * f_c[1]]
                continue
            pd.append(d)
            pv.append(dd)
            f = float(e.law.force(d, dd))
            fn = e.side * f * e.normal
            u[e.port] += (fn.real, fn.imag)
            rates += [f, float(e.law.dissipation_rate(f, d, dd)), f * tau,
                      (fn.conjugate() * dirc).real * dw[e.port]]
        self._last_eval = (y, pd, pv)
        g = self._modal_force(u) + self._g_modal + load
        ddq = g - self.modal_damping * dq - self.omega ** 2 * q
        v = dw * dirc
        return np.concatenate([dq, ddq, rates, [float(self.modal_damping @ (dq * dq)), 0.0],
                               np.concatenate([v, s * v, (s * s) * v]).view(float), quads])

    def _step_impl(self, t, h, inputs):
        circles = self.circles
        if not circles:
            return super()._step_impl(t, h, inputs)
        m = self.n_modes
        self.switch_log = []
        self._t0, self._h = t, h
        self.aux[2:-2:4] = 0.0          # first moments are per step
        for e in circles:
            e.quad[:] = 0.0
        if not np.any(self._switch(t, self.x) > 0):
            G = (self._modal_force(inputs.coeffs) if inputs is not None
                 else np.zeros((1, m))).copy()
            G[0] += self._g_modal
            q1, dq1 = self._stepper.step_modal(self.x[:m], self.x[m:], h, G)
            y1 = np.concatenate([q1, dq1])
            if not np.any(self._switch(t + h, y1) > 0):
                self._account_damping(h, self.x, y1)
                self._gauss_moments(h, G, inputs is not None and bool(np.any(inputs.coeffs)))
                self.x[:] = y1
                return
        na, nm = self.aux.size, 6 * self.n_ports
        y0 = np.concatenate([self.x, self.aux, np.zeros(nm + 4 * len(circles))])
        y1 = self._rk4.integrate(lambda tt, yy: self._rhs(tt, yy, inputs), t, y0, t + h,
                                 self._switch, self._on_switch, probe=self._probe,
                                 peak=self.peak)
        self._last_eval = (None, None, None)
        self.x[:] = y1[:2 * m]
        self.aux[:] = y1[2 * m:2 * m + na]
        self.port_moments = y1[2 * m + na:2 * m + na + nm].view(complex).reshape(3, self.n_ports)
        quads = y1[2 * m + na + nm:].reshape(-1, 4)
        for e, qd in zip(circles, quads):
            e.quad[:] = qd
