"""A plane body as a subsystem: a :class:`~cosim.sides.fem.StructureSubsystem`
whose records are its modal coordinates and its ports, never the whole
field (a body of 38k DOFs would otherwise add 76k columns to every row of
the series).  The field is the kept modes times the recorded coordinates,
``u = Phi q``: :meth:`PlaneSubsystem.field` gives it back."""
from __future__ import annotations

import numpy as np

from cosim.core.subsystem import SubsystemState
from cosim.sides.fem import StructureSubsystem
from cosim.sides.kernel import retired
from cosim.sides.plane_circle import CircleHosting

__all__ = ["PlaneSubsystem"]


class PlaneSubsystem(CircleHosting, StructureSubsystem):
    """A :class:`fem.plane.PlaneStructure` reduced to the modes of its basis
    (same parameters as :class:`~cosim.sides.fem.StructureSubsystem`); its
    ports slide along its boundary (:meth:`slide_port`), and it hosts circle
    contacts (:mod:`cosim.sides.plane_circle`)."""

    #: its compiled kernel's C face mirrors its Python step and outputs (LoopFace)
    loop_face_faithful = True

    #: its ports slide in Python (:meth:`slide_port`), never by the compiled face
    #: of a line structure
    capabilities = (StructureSubsystem.capabilities - {"compiled_follow"}) | {"sliding_ports"}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._names = [f"mode{i + 1}" for i in range(self.n_modes)]

    def named_values(self, X):
        """Modal coordinates of states ``X`` (..., 2 m): names, q, dq."""
        m = self.n_modes
        return self._names, X[..., :m], X[..., m:2 * m]

    def sliding_loop(self, port: int):
        """The closed boundary chain ``port`` slides along
        (:class:`fem.plane.boundary.BoundaryLoop`), made on the first call
        from the port's first point.

        Raises
        ------
        fem.plane.MeshError
            If the boundary touches itself at a vertex.
        """
        from fem.plane.boundary import BoundaryLoop

        loops = self.__dict__.setdefault("_loops", {})
        loop = loops.get(port)
        if loop is None:
            group, s = self.port_coordinates[port]
            loop = BoundaryLoop(self.structure, group, s)
            loop.set_modes(self.Phi)
            loops[port] = loop
        return loop

    def slide_port(self, port: int, point, x) -> np.ndarray:
        """Move ``port`` to the point of the deformed boundary closest to the
        world ``point`` for the state ``x`` (node-to-segment over the
        closed boundary chain through the port's first segment,
        :class:`fem.plane.boundary.BoundaryLoop`, across corners onto the
        next segment), and return the outward unit normal there.

        The port's row becomes the displacement of that material point
        projected on that normal, and it moves along the normal: its
        position's component along the normal is the deformed boundary's,
        so the gap ``n . (p - x_b)`` a contact reads is the signed distance
        to the deformed boundary, whose rate is ``n . (v_p - v_b)`` exactly.
        A contact this side hosts at the port turns its normal with it."""
        loop = self.sliding_loop(port)
        m = self.n_modes
        k, xi, n, _ = loop.project(point, np.asarray(x, float)[:m])
        self.__dict__.setdefault("_on_segment", {})[port] = (k, xi)
        row = n @ loop.modal_rows(k, xi)
        if np.array_equal(row, self._R[port]) and np.array_equal(n, self._dirs[port]):
            return n
        self._R[port] = row
        self._ref[port] = loop.position(k, xi)
        self._dirs[port] = n              # in place: the compiled kernel reads it
        self._dirc[port] = complex(n[0], n[1])
        self.port_coordinates[port] = (loop.name, loop.coordinate(k, xi))
        for j, e in enumerate(self._embedded):
            if e.port == port:
                e.normal = complex(n[0], n[1])
                if self._kernel:
                    self._kernel.set_normal(j, e.normal)
        if any(e.port == port for e in self._embedded):
            self._bases = {}            # the springs' modes hang on the port's row
        if self._kernel:
            self._kernel.forget_bases()
        return n

    def correct_following(self, port: int, law, correction) -> None:
        """Keep the static correction of the contact that follows along
        ``port`` on its present point: ``law`` (the contact's own copy of a
        linear law, :func:`cosim.scene.plane_build.corrected_law`) has its
        ``contact_stiffness`` set to ``k / (1 + k c_r)`` by
        :meth:`follow_stiffness` each time the port moves, ``k`` the
        stiffness the scene gave and ``c_r`` the dropped modes' compliance
        at the port's point (``correction``, a
        :class:`fem.plane.reduce.StaticCorrection`: per visited segment)."""
        corr = self.__dict__.setdefault("_follow_corr", {})
        # the law, the scene's stiffness, the correction, the energy booked
        corr[port] = [law, float(law.contact_stiffness), correction, 0.0]
        self.follow_stiffness(port, lambda: 0.0)

    def follow_stiffness(self, port: int, penetration) -> None:
        """After :meth:`slide_port`: the corrected stiffness of the contact
        following along ``port`` at the port's present point.

        The law is changed in place (every holder of the contact's law reads
        it: the coupler, this side's embedded contact; the compiled kernel,
        which copies its springs' stiffnesses when built, is built again,
        and the closed-form bases, which hang on the stiffness, are
        dropped).  A change of stiffness at the penetration ``d =
        penetration()`` changes the spring's stored energy by
        ``(k1 - k0) d^2 / 2`` with no work of any force: that is the work of
        the reduction (the dropped modes' static part of the field, which
        the correction stands for, differs from point to point), booked as
        energy supplied to this side (``ledger()[1]``) so the ledger closes."""
        entry = self.__dict__.get("_follow_corr", {}).get(port)
        if entry is None:
            return
        law, k_own, correction, _ = entry
        seg = self.__dict__.get("_on_segment", {}).get(port)
        if seg is None:                 # its first point
            c_r = correction.compliance(self.port_coordinates[port], self._dirs[port])
        else:                           # where slide_port put it
            c_r = correction.row_compliance(*self.sliding_loop(port).point_row(
                *seg, self._dirs[port]))
        k = k_own / (1.0 + k_own * c_r)
        if k == law.contact_stiffness:
            return
        d = float(penetration())
        before = float(law.potential(d))
        object.__setattr__(law, "contact_stiffness", k)   # the contact's own copy
        booked = float(law.potential(d)) - before
        entry[3] += booked
        self.aux[-1] += booked
        self._forget_springs()

    def follow_supplied(self, port: int) -> float:
        """Energy [J] the static correction of the contact following along
        ``port`` has supplied to its spring so far (:meth:`follow_stiffness`;
        0 without one): the part of ``ledger()[1]`` that is that contact's."""
        entry = self.__dict__.get("_follow_corr", {}).get(port)
        return 0.0 if entry is None else float(entry[3])

    def _forget_springs(self) -> None:
        """A hosted spring's stiffness changed: drop the closed-form bases,
        and the compiled kernel (built again, with the new stiffness, on the
        next step that it takes)."""
        self._bases = {}
        if self._kernel:
            self._kernel = retired(self._kernel)

    def get_state(self):
        """As the structure's, with each following contact's corrected
        stiffness and the energy booked for it: a step taken again starts
        from the stiffness its booked energy (``aux``) goes with."""
        st = super().get_state()
        entries = list(self.__dict__.get("_follow_corr", {}).values())
        if entries:
            st.x = np.concatenate([st.x, [e[0].contact_stiffness for e in entries],
                                   [e[3] for e in entries]])
        return st

    def set_state(self, state):
        entries = list(self.__dict__.get("_follow_corr", {}).values())
        if not entries:
            return super().set_state(state)
        n = len(entries)
        ks, booked = state.x[-2 * n:-n], state.x[-n:]
        super().set_state(SubsystemState(state.t, state.x[:-2 * n], state.aux,
                                         state.n_steps, state.status, state.peak))
        changed = False
        for k, b, e in zip(ks, booked, entries):
            changed |= float(k) != e[0].contact_stiffness
            object.__setattr__(e[0], "contact_stiffness", float(k))
            e[3] = float(b)
        if changed:
            self._forget_springs()

    def ledger(self):
        """Energy dissipated by damping, and supplied by the static
        correction of a following contact (:meth:`follow_stiffness`) [J]."""
        return float(self.aux[-2]), float(self.aux[-1])

    def field(self, q) -> np.ndarray:
        """World displacement of every vertex for modal coordinates ``q``
        (..., m): shape (..., N, 2) [m]."""
        return self.structure.nodal_displacement(np.asarray(q, float) @ self.Phi.T)
