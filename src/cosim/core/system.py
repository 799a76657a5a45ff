"""The coupled system: subsystems, and the contacts that link their ports
(each a :class:`~cosim.core.links.ContactLink`)."""
from __future__ import annotations

import numpy as np

from couplers.contact import penetrations
from couplers.modes import GRASPED

from cosim.core.following import MovingPorts
from cosim.core.links import PLACEMENTS, ContactLink, HostedContact
from cosim.core.subsystem import StepInput, Subsystem

__all__ = ["ContactLink", "CoupledSystem", "HostedContact", "PLACEMENTS"]

class CoupledSystem(MovingPorts):
    """Subsystems and contacts, with the bookkeeping every scheme shares.

    Contacts placed ``"embedded"`` are handed to their moving side at
    construction; the others are the scheme's to exchange.

    Forces are exchanged as scalar **rows**: row ``c < n_contacts`` is
    contact ``c``'s normal force (on side ``a`` along its normal); a contact
    with a grasp or with friction has a second, tangential row
    (``tangent_row[c]``, after all normal rows) along ``t = (-n_y, n_x)``.
    ``penetrations`` gives per row the penetration and its rate (normal rows)
    or the tangential coordinate of ``x_a - x_b`` from the grasp anchor and
    its rate (tangential rows); ``forces`` maps them to row forces in the
    connections' current modes (:attr:`connections`, None when no contact
    has a connection, so plain contacts run no connection code).
    """

    def __init__(self, subsystems: list[Subsystem], links: list[ContactLink]):
        self.subsystems = list(subsystems)
        self.links = list(links)
        self.names = [s.name for s in self.subsystems]
        self.contact_names = [ln.contact.name for ln in self.links]
        self.n_contacts = len(self.links)
        self.coupler = np.array([i for i, ln in enumerate(self.links)
                                 if ln.placement == "coupler"], dtype=int)
        self._init_rows()
        # embedded: contact index -> (subsystem index, slot in its aux)
        self.embedded: dict[int, tuple[int, int]] = {}
        # hosted (embedded against a moving partner): contact index -> HostedContact
        self.hosted: dict[int, HostedContact] = {}
        slots = [0] * len(self.subsystems)
        for i, ln in enumerate(self.links):
            if ln.placement != "embedded":
                continue
            a, b = self.subsystems[ln.sub_a], self.subsystems[ln.sub_b]
            if a.rigid and b.rigid:
                raise ValueError(f"contact `{ln.contact.name}`: placement `embedded` needs a "
                                 f"moving side")
            if a.rigid or b.rigid:
                own = ln.sub_a if b.rigid else ln.sub_b
            else:
                own = ln.sub_a if ln.host is None else ln.host
                if own not in (ln.sub_a, ln.sub_b):
                    raise ValueError(f"contact `{ln.contact.name}`: its host must be one of "
                                     f"its sides")
            side = 1.0 if own == ln.sub_a else -1.0
            partner = ln.sub_b if side > 0 else ln.sub_a
            own_port = ln.port_a if side > 0 else ln.port_b
            partner_port = ln.port_b if side > 0 else ln.port_a
            psub = self.subsystems[partner]
            ppos, pvel = psub.outputs(0.0, psub.x)
            emb = self.subsystems[own].embed_contact(ln.contact, own_port, side,
                                                     ppos[partner_port], pvel[partner_port])
            self.embedded[i] = (own, slots[own])
            if not psub.rigid:
                if ln.connection is not None:
                    raise ValueError(f"contact `{ln.contact.name}`: a grasp or friction "
                                     f"between two moving sides is exchanged by the scheme; "
                                     f"use placement `coupler`")
                self.hosted[i] = HostedContact(own, slots[own], partner, partner_port, emb)
            if ln.connection is not None:
                if "connections" not in self.subsystems[own].capabilities:
                    raise ValueError(f"contact `{ln.contact.name}`: subsystem "
                                     f"`{self.subsystems[own].name}` cannot carry an embedded "
                                     f"grasp or friction; use placement `coupler`")
                from cosim.core.connection_modes import EmbeddedConnection   # only where a contact has one
                self.subsystems[own].attach_connection(
                    slots[own], EmbeddedConnection(self.connections, i, ln.contact.normal, side))
            slots[own] += 1
        # embedded contacts grouped by host: (host, contact indices, slots)
        hosts = sorted({s for s, _ in self.embedded.values()})
        self._embedded_groups = [
            (s, np.array([c for c, (h, _) in self.embedded.items() if h == s], dtype=int),
             np.array([k for h, k in self.embedded.values() if h == s], dtype=int))
            for s in hosts]
        #: the contacts whose surface point follows the point above it
        #: (:meth:`update_followers`)
        self.followers = [ln for ln in self.links if ln.follow]
        for ln in self.followers:
            if "moving_ports" not in self.subsystems[ln.sub_b].capabilities:
                raise ValueError(f"contact `{ln.contact.name}`: `follow` needs a structure as "
                                 f"side b")
            if ln.placement == "embedded" and ln.host == ln.sub_a:
                raise ValueError(f"contact `{ln.contact.name}`: a following contact hosted by "
                                 f"its point's side (`{self.subsystems[ln.sub_a].name}`) "
                                 f"would miss the surface's slope force; host it in "
                                 f"`{self.subsystems[ln.sub_b].name}` or use placement "
                                 f"`coupler`")
        #: following contacts: index, and n . dx_b/ds at the surface point now
        self._follow_index = np.array([c for c, ln in enumerate(self.links) if ln.follow],
                                      dtype=int)
        self._follow_slope = np.zeros(self._follow_index.size)
        self._follow_axis = np.zeros((self._follow_index.size, 2))
        self._normals = np.array([ln.contact.normal for ln in self.links]).reshape(-1, 2)
        self._offsets = np.array([ln.contact.offset for ln in self.links])
        self._laws = [ln.contact.law for ln in self.links]
        # each contact's two ports as rows of all subsystems' stacked outputs
        first = np.cumsum([0] + [sub.n_ports for sub in self.subsystems])
        self._row_a = np.array([first[ln.sub_a] + ln.port_a for ln in self.links], dtype=int)
        self._row_b = np.array([first[ln.sub_b] + ln.port_b for ln in self.links], dtype=int)
        # Port-force maps: flat port forces of subsystem s = G[s] @ row forces.
        self._G = []
        for s, sub in enumerate(self.subsystems):
            G = np.zeros((sub.n_ports * 2, self.n_rows))
            for r, c in enumerate(self.row_contact):
                ln = self.links[c]
                n = self._row_dir[r]
                if ln.sub_a == s:
                    G[2 * ln.port_a:2 * ln.port_a + 2, r] += n
                if ln.sub_b == s:
                    G[2 * ln.port_b:2 * ln.port_b + 2, r] -= n
            self._G.append(G)
        # Co-simulation exchanges the coupler contacts' rows, and hands a
        # hosted contact's (normal) force to its partner side.
        self._Gc = []
        for s, G in enumerate(self._G):
            mask = np.zeros(self.n_rows)
            mask[self.coupler_rows] = 1.0
            for c, partner in ((c, h.partner) for c, h in self.hosted.items()):
                if partner == s:
                    mask[c] = 1.0
            self._Gc.append(G * mask)
        self._applied: dict[int, tuple] = {}   # force polynomials of the step, and their maps
        self._work = np.zeros(self.n_rows)
        #: the rows whose force a scheme hands over (coupler rows, hosted contacts)
        self.exchanged = np.array(sorted(set(self.coupler_rows.tolist()) | set(self.hosted)),
                                  dtype=int)
        #: hosted circle contacts (cosim.core.circles): contact index -> HostedContact
        self.circles = {c: hc for c, hc in self.hosted.items() if hasattr(hc.embedded, "circle")}
        if self.connections is not None:
            self._close_at_start()

    # ------------------------------------------------------------------ rows
    # ---------------------------------------- read-only faces of the layout
    @staticmethod
    def _read_only(a) -> np.ndarray:
        v = a.view()
        v.flags.writeable = False
        return v

    @property
    def contact_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Each contact's two ports (side a's, side b's) as rows of the
        subsystems' stacked outputs: two (n_contacts,) int arrays (read-only)."""
        return self._read_only(self._row_a), self._read_only(self._row_b)

    @property
    def contact_normals(self) -> np.ndarray:
        """Each contact's normal, (n_contacts, 2) (read-only; a following
        contact's turns with its surface)."""
        return self._read_only(self._normals)

    @property
    def contact_offsets(self) -> np.ndarray:
        """Each contact's offset [m], (n_contacts,) (read-only)."""
        return self._read_only(self._offsets)

    @property
    def exchange_maps(self) -> tuple:
        """Per subsystem, the (2 n_ports, n_rows) map of the row forces a
        scheme hands it (the exchanged rows only) to its flat port forces
        (read-only; a following contact turns side a's column in place)."""
        return tuple(self._read_only(G) for G in self._Gc)

    def _init_rows(self) -> None:
        nc = self.n_contacts
        conns = [ln.connection for ln in self.links]
        self.connections = None
        if any(k is not None for k in conns):
            from cosim.core.connection_modes import ConnectionSet       # only where a contact has one
            self.connections = ConnectionSet(self.contact_names,
                                             [ln.contact.law for ln in self.links], conns)
        self.tangent_row = np.full(nc, -1, dtype=int)
        extra = [c for c, k in enumerate(conns) if k is not None and k.tangential]
        self.tangent_row[extra] = nc + np.arange(len(extra))
        self.n_rows = nc + len(extra)
        #: the contact each row belongs to
        self.row_contact = np.array(list(range(nc)) + extra, dtype=int)
        normals = [np.asarray(ln.contact.normal, float) for ln in self.links]
        self._row_dir = np.array(normals + [np.array([-normals[c][1], normals[c][0]])
                                            for c in extra]).reshape(-1, 2)
        #: names of the rows: the contact's name, NAME.t for a tangential row
        self.row_names = list(self.contact_names) + [f"{self.contact_names[c]}.t"
                                                     for c in extra]
        coupler = set(int(c) for c in self.coupler)
        self.coupler_rows = np.array([r for r, c in enumerate(self.row_contact) if c in coupler],
                                     dtype=int)

    def _close_at_start(self) -> None:
        cs = self.connections
        d, dd = self.penetrations(self.outputs())
        for c in cs.index:
            conn = cs.connections[c]
            if conn.grasp is not None and conn.close.kind == "start":
                self.set_mode(c, 0.0, GRASPED, d, dd)
        self.switch_modes(0.0, d, dd)
        cs.lost[:] = 0.0        # switches at t = 0 make the initial state: nothing is lost

    def set_mode(self, c: int, t: float, mode: int, d, dd) -> None:
        """Switch contact ``c`` to ``mode`` at ``t``, given the rows ``d``, ``dd`` there."""
        r = self.tangent_row[c]
        s = self.connections.anchor[c] + (d[r] if r >= 0 else 0.0)
        self.connections.set_mode(c, t, mode, float(d[c]), float(dd[c]), float(s))

    def switch_modes(self, t: float, d, dd, touch: bool = True) -> bool:
        """Switch the connections whose trigger has come at ``t`` (a
        communication point): ``touch`` grasps of contacts whose law gives a
        force (unless ``touch`` is False), then ``time`` and ``after``
        triggers until none is due.  ``d``, ``dd`` are the rows at ``t``.
        True when a mode changed (the caller recomputes rows and forces:
        a grasp moves the tangential anchor)."""
        cs = self.connections
        if cs is None:
            return False
        changed = False
        if touch:
            for c in cs.index:
                law = self.links[c].contact.law
                if cs.closes_on_touch(c) and float(law.switch(d[c], dd[c])) > 0:
                    self.set_mode(c, t, GRASPED, d, dd)
                    changed = True
        for _ in range(2 * len(cs.index) + 1):       # chains of `after` conditions
            due = cs.due(t)
            if not due:
                break
            for c, mode in due:
                self.set_mode(c, t, mode, d, dd)
            changed = True
        return changed

    def contact_mobility(self, c: int) -> float:
        """``n^T J M^-1 J^T n`` of contact ``c``'s two ports, summed, in the
        subsystems' present state [1/kg]: one over the reduced mass the
        contact's spring sees along its normal."""
        ln = self.links[c]
        n = ln.contact.normal
        return (self.subsystems[ln.sub_a].port_mobility(ln.port_a, n)
                + self.subsystems[ln.sub_b].port_mobility(ln.port_b, n))

    def in_touch(self, f) -> np.ndarray:
        """Per contact: carries force (or is grasped)."""
        on = np.asarray(f[:self.n_contacts]) > 0
        if self.connections is not None:
            on = on | (self.connections.mode == GRASPED)
        return on

    # ------------------------------------------------------------- states
    def outputs(self, states=None):
        """Port positions and velocities of every subsystem at its own state."""
        return [sub.outputs(sub.t, sub.x if states is None else states[i])
                for i, sub in enumerate(self.subsystems)]

    def penetrations(self, outs):
        """Penetration and rate of every contact, from subsystem outputs."""
        pos = np.concatenate([o[0] for o in outs])
        vel = np.concatenate([o[1] for o in outs])
        dx = pos[self._row_a] - pos[self._row_b]
        dv = vel[self._row_a] - vel[self._row_b]
        d, dd = penetrations(self._normals, self._offsets, dx, dv)
        if self._follow_index.size:     # the surface point moves with x_a (update_followers)
            fi = self._follow_index
            dd[fi] += self._follow_slope * np.einsum("cx,cx->c", vel[self._row_a[fi]],
                                                     self._follow_axis)
        if self.n_rows > self.n_contacts:
            nc, ct = self.n_contacts, self.row_contact[self.n_contacts:]
            t = self._row_dir[nc:]
            e = np.einsum("cx,cx->c", dx[ct], t) - self.connections.anchor[ct]
            de = np.einsum("cx,cx->c", dv[ct], t)
            d, dd = np.concatenate([d, e]), np.concatenate([dd, de])
        if self.circles:
            from cosim.core.circles import circle_rows
            circle_rows(self, outs, d, dd)
        return d, dd

    def forces(self, d, dd, which=None):
        """Forces of the rows ``which`` (all by default), in the current modes."""
        if self.connections is None and not self.circles:
            idx = range(self.n_contacts) if which is None else which
            laws = self._laws
            return np.array([laws[c].evaluate(d[c], dd[c])[0] for c in idx], dtype=float)
        f = np.zeros(self.n_rows)
        cs = self.connections
        for c, ln in enumerate(self.links):
            if ln.connection is None:
                f[c] = float(ln.contact.law.force(d[c], dd[c]))
                continue
            r = self.tangent_row[c]
            fn, ft = cs.forces(c, d[c], dd[c], *((d[r], dd[r]) if r >= 0 else (0.0, 0.0)))
            f[c] = fn
            if r >= 0:
                f[r] = ft
        if self.circles:
            from cosim.core.circles import circle_forces
            circle_forces(self, f)
        return f if which is None else f[np.asarray(which, dtype=int)]

    def dissipation_rates(self, f, d, dd) -> np.ndarray:
        """Power dissipated by each contact [W] (normal and tangential rows)."""
        out = np.zeros(self.n_contacts)
        cs = self.connections
        for c, ln in enumerate(self.links):
            if ln.connection is None:
                out[c] = ln.contact.law.dissipation_rate(f[c], d[c], dd[c])
                continue
            r = self.tangent_row[c]
            ft, e, de = (f[r], d[r], dd[r]) if r >= 0 else (0.0, 0.0, 0.0)
            out[c] = cs.power(c, f[c], ft, d[c], dd[c], e, de)
        return out

    def contact_potentials(self, d) -> np.ndarray:
        """(n_contacts,) elastic energy stored in each contact [J] (its law's,
        or its connection's in the current mode), from the rows ``d``."""
        out = np.zeros(self.n_contacts)
        for c, ln in enumerate(self.links):
            if ln.connection is None:
                out[c] = float(ln.contact.law.potential(d[c]))
            else:
                r = self.tangent_row[c]
                out[c] = self.connections.potential(c, d[c], d[r] if r >= 0 else 0.0)
        if self.circles:
            from cosim.core.circles import circle_potentials
            circle_potentials(self, out)
        return out

    def contact_potential(self, d) -> float:
        if self.connections is None and not self.circles:
            laws = self._laws
            return float(sum([laws[c].potential(d[c]) for c in range(self.n_contacts)]))
        return float(np.sum(self.contact_potentials(d)))

    def energy(self, d) -> float:
        """Energy of the subsystems plus the elastic energy of the contacts [J]."""
        return float(sum([s.energy() for s in self.subsystems])) + self.contact_potential(d)

    def step_input(self, s: int, t0: float, h: float, coeffs: np.ndarray) -> StepInput:
        """Port forces of subsystem ``s`` from contact-force polynomial
        coefficients ``coeffs`` (order + 1, n_rows)."""
        sub = self.subsystems[s]
        self.book_applied(s, coeffs)
        c = coeffs @ self._Gc[s].T
        return StepInput(t0, h, c.reshape(len(coeffs), sub.n_ports, 2))

    def book_applied(self, s: int, coeffs: np.ndarray) -> None:
        """Keep ``coeffs`` (order + 1, n_rows), the force polynomial a scheme
        handed subsystem ``s`` for its step without :meth:`step_input` (a
        compiled iteration), for :meth:`collect_work`."""
        self._applied[s] = (coeffs, self._Gc[s])

    def collect_work(self, s: int) -> None:
        """Add the work the exchanged forces did on subsystem ``s`` over its
        last step (the force polynomial it was handed against its ports'
        velocity moments: exact for the polynomial)."""
        coeffs, G = self._applied.pop(s, (None, None))
        if coeffs is None:
            return
        mom = self.subsystems[s].port_moments.view(float).reshape(3, -1)
        p = coeffs.shape[0]
        self._work += np.einsum("jc,jc->c", coeffs, mom[:p] @ G)

    def exchange_work(self) -> np.ndarray:
        """(n_contacts,) work [J] the exchanged contact forces (all rows of a
        contact) did on the subsystems since the last call, and reset.  Contacts embedded in a
        host add the host's own side through :meth:`embedded_work`."""
        for s in list(self._applied):
            self.collect_work(s)
        work = np.bincount(self.row_contact, weights=self._work, minlength=self.n_contacts)
        self._work = np.zeros(self.n_rows)
        return work

    def discard_work(self) -> None:
        """Forget the work of steps that are being rolled back."""
        self._applied = {}
        self._work = np.zeros(self.n_rows)

    def embedded_work(self) -> np.ndarray:
        """(n_contacts,) work [J] embedded contacts did on their hosts so far."""
        out = np.zeros(self.n_contacts)
        for s, contacts, slots in self._embedded_groups:
            out[contacts] = self.subsystems[s].embedded_quadratures()[slots, 3]
        return out

    def take_peaks(self) -> np.ndarray:
        """(n_contacts,) each embedded contact's largest penetration [m] since
        the last call, as its host's integrator located it inside the steps
        (0 for the other contacts, and for rigid laws, whose impact is an
        instant); the hosts start again from 0."""
        out = np.zeros(self.n_contacts)
        if not self.embedded:
            return out
        taken = {}
        for c, (s, slot) in self.embedded.items():
            if s not in taken:
                taken[s] = self.subsystems[s].take_peaks()
            if not self.links[c].contact.law.rigid:
                out[c] = taken[s][slot]
        return out

    def embedded_quadratures(self):
        """(n_contacts, 2) impulse and dissipated energy of embedded contacts."""
        out = np.zeros((self.n_contacts, 2))
        for s, contacts, slots in self._embedded_groups:
            out[contacts] = self.subsystems[s].embedded_quadratures()[slots, :2]
        return out

    def hosted_view_forces(self, outs) -> dict:
        """Force of each hosted contact as its host sees it now, against the
        partner motion it was given, from outputs ``outs``."""
        out = {}
        for c, (host, _, _, _, emb) in self.hosted.items():   # HostedContact
            sub = self.subsystems[host]
            pos, vel = outs[host]
            d, dd = emb.penetration(sub.t, complex(*pos[emb.port]), complex(*vel[emb.port]))
            out[c] = float(emb.law.force(d, dd))
        return out

    def hosted_force(self, c: int, h: float, impulse_before: float) -> np.ndarray:
        """Force that hosted contact ``c`` exerted over its host's last step of
        length ``h``, as the linear polynomial in ``s`` (coefficients (2,),
        lowest first) with the same impulse and first moment: the L2
        projection of the force history on linear functions.  The partner
        side receives it, so momentum passes over exactly."""
        if c in self.circles:
            from cosim.core.circles import circle_hosted_force
            return circle_hosted_force(self, c, h)
        host, slot = self.embedded[c]
        imp, _, mom, _ = self.subsystems[host].embedded_quadratures()[slot]
        m0 = (imp - impulse_before) / h          # int_0^1 f ds
        m1 = mom / (h * h)                       # int_0^1 f s ds
        return np.array([4.0 * m0 - 6.0 * m1, 12.0 * m1 - 6.0 * m0])

    def get_state(self):
        """Snapshot of every subsystem and of the connections' modes."""
        states = [s.get_state() for s in self.subsystems]
        if self.connections is not None:
            states.append(self.connections.snapshot())
        return states

    def set_state(self, states):
        for s, st in zip(self.subsystems, states):
            s.set_state(st)
        if self.connections is not None:
            self.connections.restore(states[len(self.subsystems)])

    # ----------------------------------------------- monolithic (stacked) face
    def stacked(self):
        """Offsets of each subsystem's state in the stacked vector."""
        sizes = [s.n_states for s in self.subsystems]
        return np.concatenate([[0], np.cumsum(sizes)]).astype(int)

    def port_forces(self, s: int, f: np.ndarray) -> np.ndarray:
        sub = self.subsystems[s]
        return (self._G[s] @ f).reshape(sub.n_ports, 2)
