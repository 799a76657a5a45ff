"""The coupled system: subsystems, and the contacts that link their ports."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from couplers import PointContact

from .subsystem import StepInput, Subsystem

__all__ = ["ContactLink", "CoupledSystem", "PLACEMENTS"]

#: Where a contact's penalty law is evaluated in a co-simulation.
PLACEMENTS = ("embedded", "coupler")


@dataclass(frozen=True)
class ContactLink:
    """A contact between port ``port_a`` of subsystem ``sub_a`` (the point)
    and port ``port_b`` of subsystem ``sub_b`` (the surface).

    ``placement`` is ``"embedded"`` (evaluated inside one side's integrator:
    the moving side against a rigid partner, or the side ``host`` against the
    other side's port moving as the scheme extrapolates or interpolates it)
    or ``"coupler"`` (the coupling scheme exchanges the force).
    """

    contact: PointContact
    sub_a: int
    port_a: int
    sub_b: int
    port_b: int
    placement: str
    follow: bool = False
    host: int | None = None


class CoupledSystem:
    """Subsystems and contacts, with the bookkeeping every scheme shares.

    Contacts placed ``"embedded"`` are handed to their moving side at
    construction; the others are the scheme's to exchange.
    """

    def __init__(self, subsystems: list[Subsystem], links: list[ContactLink]):
        self.subsystems = list(subsystems)
        self.links = list(links)
        self.names = [s.name for s in self.subsystems]
        self.contact_names = [ln.contact.name for ln in self.links]
        self.n_contacts = len(self.links)
        self.coupler = np.array([i for i, ln in enumerate(self.links)
                                 if ln.placement == "coupler"], dtype=int)
        # embedded: contact index -> (subsystem index, slot in its aux)
        self.embedded: dict[int, tuple[int, int]] = {}
        # hosted (embedded against a moving partner): contact index ->
        # (host, slot, partner, partner port, EmbeddedContact)
        self.hosted: dict[int, tuple] = {}
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
                self.hosted[i] = (own, slots[own], partner, partner_port, emb)
            slots[own] += 1
        self._followers = [ln for ln in self.links if ln.follow]
        for ln in self._followers:
            if not hasattr(self.subsystems[ln.sub_b], "move_port"):
                raise ValueError(f"contact `{ln.contact.name}`: `follow` needs a structure as "
                                 f"side b")
        self._normals = np.array([ln.contact.normal for ln in self.links]).reshape(-1, 2)
        self._offsets = np.array([ln.contact.offset for ln in self.links])
        # Port-force maps: flat port forces of subsystem s = G[s] @ contact forces.
        self._G = []
        for s, sub in enumerate(self.subsystems):
            G = np.zeros((sub.n_ports * 2, self.n_contacts))
            for c, ln in enumerate(self.links):
                n = np.asarray(ln.contact.normal)
                if ln.sub_a == s:
                    G[2 * ln.port_a:2 * ln.port_a + 2, c] += n
                if ln.sub_b == s:
                    G[2 * ln.port_b:2 * ln.port_b + 2, c] -= n
            self._G.append(G)
        # Co-simulation exchanges the coupler contacts' forces, and hands a
        # hosted contact's force to its partner side.
        self._Gc = []
        for s, G in enumerate(self._G):
            mask = np.zeros(self.n_contacts)
            mask[self.coupler] = 1.0
            for c, (_, _, partner, _, _) in self.hosted.items():
                if partner == s:
                    mask[c] = 1.0
            self._Gc.append(G * mask)
        self._applied: dict[int, np.ndarray] = {}      # force polynomials of the step
        self._work = np.zeros(self.n_contacts)
        #: the contacts whose force a scheme hands over (coupler and hosted)
        self.exchanged = np.array(sorted(set(self.coupler.tolist()) | set(self.hosted)),
                                  dtype=int)

    # ---------------------------------------------------- moving surface points
    def update_followers(self, outs) -> None:
        """Move each following contact's surface port under its point: the
        material coordinate of side ``b`` below side ``a``'s port."""
        for ln in self._followers:
            sub = self.subsystems[ln.sub_b]
            sub.move_port(ln.port_b, sub.material_coordinate(outs[ln.sub_a][0][ln.port_a]))

    # ------------------------------------------------------------- states
    def outputs(self, states=None):
        """Port positions and velocities of every subsystem at its own state."""
        return [sub.outputs(sub.t, sub.x if states is None else states[i])
                for i, sub in enumerate(self.subsystems)]

    def penetrations(self, outs):
        """Penetration and rate of every contact, from subsystem outputs."""
        xa = np.array([outs[ln.sub_a][0][ln.port_a] for ln in self.links]).reshape(-1, 2)
        va = np.array([outs[ln.sub_a][1][ln.port_a] for ln in self.links]).reshape(-1, 2)
        xb = np.array([outs[ln.sub_b][0][ln.port_b] for ln in self.links]).reshape(-1, 2)
        vb = np.array([outs[ln.sub_b][1][ln.port_b] for ln in self.links]).reshape(-1, 2)
        n = self._normals
        d = self._offsets - np.einsum("cx,cx->c", xa - xb, n)
        dd = -np.einsum("cx,cx->c", va - vb, n)
        return d, dd

    def forces(self, d, dd, which=None):
        """Penalty forces of the contacts ``which`` (all by default)."""
        idx = range(self.n_contacts) if which is None else which
        return np.array([float(self.links[c].contact.law.force(d[c], dd[c])) for c in idx])

    def contact_potential(self, d) -> float:
        return float(sum(ln.contact.law.potential(d[c]) for c, ln in enumerate(self.links)))

    def energy(self, d) -> float:
        """Energy of the subsystems plus the elastic energy of the contacts [J]."""
        return float(sum(s.energy() for s in self.subsystems)) + self.contact_potential(d)

    def step_input(self, s: int, t0: float, h: float, coeffs: np.ndarray) -> StepInput:
        """Port forces of subsystem ``s`` from contact-force polynomial
        coefficients ``coeffs`` (order + 1, n_contacts)."""
        sub = self.subsystems[s]
        self._applied[s] = coeffs
        c = coeffs @ self._Gc[s].T
        return StepInput(t0, h, c.reshape(len(coeffs), sub.n_ports, 2))

    def collect_work(self, s: int) -> None:
        """Add the work the exchanged forces did on subsystem ``s`` over its
        last step (the force polynomial it was handed against its ports'
        velocity moments: exact for the polynomial)."""
        coeffs = self._applied.pop(s, None)
        if coeffs is None:
            return
        mom = self.subsystems[s].port_moments.view(float).reshape(3, -1)
        p = coeffs.shape[0]
        self._work += np.einsum("jc,jc->c", coeffs, mom[:p] @ self._Gc[s])

    def exchange_work(self) -> np.ndarray:
        """(n_contacts,) work [J] the exchanged contact forces did on the
        subsystems since the last call, and reset.  Contacts embedded in a
        host add the host's own side through :meth:`embedded_work`."""
        for s in list(self._applied):
            self.collect_work(s)
        work, self._work = self._work, np.zeros(self.n_contacts)
        return work

    def discard_work(self) -> None:
        """Forget the work of steps that are being rolled back."""
        self._applied = {}
        self._work = np.zeros(self.n_contacts)

    def embedded_work(self) -> np.ndarray:
        """(n_contacts,) work [J] embedded contacts did on their hosts so far."""
        out = np.zeros(self.n_contacts)
        for c, (s, slot) in self.embedded.items():
            out[c] = self.subsystems[s].embedded_quadratures()[slot, 3]
        return out

    def embedded_quadratures(self):
        """(n_contacts, 2) impulse and dissipated energy of embedded contacts."""
        out = np.zeros((self.n_contacts, 2))
        for c, (s, slot) in self.embedded.items():
            out[c] = self.subsystems[s].embedded_quadratures()[slot, :2]
        return out

    def hosted_view_forces(self, outs) -> dict:
        """Force of each hosted contact as its host sees it now, against the
        partner motion it was given, from outputs ``outs``."""
        out = {}
        for c, (host, _, _, _, emb) in self.hosted.items():
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
        host, slot = self.embedded[c]
        imp, _, mom, _ = self.subsystems[host].embedded_quadratures()[slot]
        m0 = (imp - impulse_before) / h          # int_0^1 f ds
        m1 = mom / (h * h)                       # int_0^1 f s ds
        return np.array([4.0 * m0 - 6.0 * m1, 12.0 * m1 - 6.0 * m0])

    def get_state(self):
        return [s.get_state() for s in self.subsystems]

    def set_state(self, states):
        for s, st in zip(self.subsystems, states):
            s.set_state(st)

    # ----------------------------------------------- monolithic (stacked) face
    def stacked(self):
        """Offsets of each subsystem's state in the stacked vector."""
        sizes = [s.n_states for s in self.subsystems]
        return np.concatenate([[0], np.cumsum(sizes)]).astype(int)

    def port_forces(self, s: int, f: np.ndarray) -> np.ndarray:
        sub = self.subsystems[s]
        return (self._G[s] @ f).reshape(sub.n_ports, 2)
