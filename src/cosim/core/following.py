"""The coupled system's moving surface points: a following contact's port
moved under its point and its force turned to the deformed surface's
normal, and a circle contact's force column turned to its impulse
(:class:`MovingPorts`, a part of :class:`~cosim.core.system.CoupledSystem`)."""
from __future__ import annotations

import numpy as np

__all__ = ["MovingPorts"]


class MovingPorts:
    """The methods of :class:`~cosim.core.system.CoupledSystem` that move
    ports and turn force columns; they use its links, subsystems, force maps
    (``_G``, ``_Gc``), normals and follower arrays."""

    def update_followers(self, outs, states=None) -> None:
        """Move each following contact's surface port under its point, and
        turn the force on the point to the deformed surface's normal.

        Side ``b``'s port moves to the material coordinate ``s`` below side
        ``a``'s point ``x_a``: ``s = (x_a - o) . e`` with the structure's
        origin ``o`` and axis ``e``.  The surface point is then
        ``x_b(s, t) = o + s e + w(s, t) r`` (``r`` the deflection direction),
        and the penetration ``d = offset - n . (x_a - x_b(s, t))`` depends on
        ``x_a`` through ``s`` as well.  Its rate is

            dd = -n . (v_a - w_t r) + sigma (e . v_a),   sigma = n . (e + w' r),

        where ``w_t r`` is the port's material velocity (what
        :meth:`penetrations` takes for ``v_b``) and ``w' = dw/ds``.  A spring of
        potential ``V(d)`` and force ``f = V'(d)`` therefore acts with
        ``-dV/dx_a = f (n - sigma e)`` on the point and with ``-f n`` on the
        material point ``s`` (its consistent nodal load), and the power balance
        is exact:

            f (n - sigma e) . v_a - f n . (w_t r) = -f dd = -dV/dt.

        A force along ``n`` alone, as before, leaves ``-f sigma (e . v_a)``
        (the slope term ``w' ds/dt`` of the spring's stretch) unpaid: the
        spring's energy changed without work on either side.  So the column
        of side ``a``'s port-force maps for the contact's row becomes
        ``n - sigma e`` (``sigma = 0`` where ``s`` is clipped to the
        structure's ends, for there ``s`` no longer moves with ``x_a``), and
        :meth:`penetrations` adds the slope term to ``dd``.

        Parameters
        ----------
        outs : list
            Every subsystem's port positions and velocities.
        states : list of arrays, optional
            The subsystems' states that gave ``outs`` (default: their own
            ``x``); side ``b``'s gives ``w'``.
        """
        for i, c in enumerate(self._follow_index):
            ln = self.links[c]
            sub = self.subsystems[ln.sub_b]
            if "sliding_ports" in sub.capabilities:   # a plane body's closest boundary point
                n = sub.slide_port(ln.port_b, outs[ln.sub_a][0][ln.port_a],
                                   sub.x if states is None else states[ln.sub_b])
                self._turn_normal(c, n)
                x = sub.x if states is None else states[ln.sub_b]
                xa = np.asarray(outs[ln.sub_a][0][ln.port_a], float)
                sub.follow_stiffness(ln.port_b, lambda: ln.contact.offset - float(
                    n @ (xa - sub.outputs(0.0, x)[0][ln.port_b])))
                continue
            s_raw = sub.material_coordinate(outs[ln.sub_a][0][ln.port_a])
            s = sub.move_port(ln.port_b, s_raw)
            x = sub.x if states is None else states[ln.sub_b]
            axis = np.asarray(sub.structure.axis, float)
            n = ln.contact.normal
            sigma = float(n @ sub.surface_tangent(ln.port_b, x)) if s == s_raw else 0.0
            if s != s_raw:
                axis = np.zeros(2)
            self._follow_slope[i] = sigma
            self._follow_axis[i] = axis
            col = np.asarray(n, float) - sigma * axis
            rows = slice(2 * ln.port_a, 2 * ln.port_a + 2)
            # new arrays, not in place: a step's work is taken with the maps
            # its forces were applied through
            for maps in (self._G, self._Gc):
                G = maps[ln.sub_a]
                if G[rows, c].any() and not np.array_equal(G[rows, c], col):
                    G = G.copy()
                    G[rows, c] = col
                    maps[ln.sub_a] = G

    def reduction_work(self) -> np.ndarray:
        """(n_contacts,) energy [J] a plane body's static correction has
        supplied to each following contact's spring by changing its
        stiffness under load (:meth:`PlaneSubsystem.follow_stiffness`): no
        force's work, so not the coupling's error either."""
        out = np.zeros(len(self.links))
        for c in self._follow_index:
            ln = self.links[c]
            supplied = getattr(self.subsystems[ln.sub_b], "follow_supplied", None)
            if supplied is not None:
                out[c] = supplied(ln.port_b)
        return out

    def _turn_normal(self, c: int, n) -> None:
        """Contact ``c`` now reads and pushes along ``n`` (``-n`` on ``b``): a
        plane body's boundary turned under a following point (no slope
        term: ``b``'s is the closest point, :meth:`PlaneSubsystem.slide_port`)."""
        self._normals[c] = self._row_dir[c] = n = np.asarray(n, float)
        ln = self.links[c]
        for sub, port, col in ((ln.sub_a, ln.port_a, n), (ln.sub_b, ln.port_b, -n)):
            rows = slice(2 * port, 2 * port + 2)
            for maps in (self._G, self._Gc):
                G = maps[sub]
                if G[rows, c].any() and not np.array_equal(G[rows, c], col):
                    maps[sub] = G = G.copy()    # new arrays, as update_followers makes
                    G[rows, c] = col

    def set_port_column(self, s: int, port: int, c: int, column) -> None:
        """Row ``c``'s force acts on port ``port`` of subsystem ``s`` along ``column``
        (new maps: a step's work is taken with the maps it was applied through)."""
        for maps in (self._G, self._Gc):
            G = maps[s].copy()
            G[2 * port:2 * port + 2, c] = column
            maps[s] = G
