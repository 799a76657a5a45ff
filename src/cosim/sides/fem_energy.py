"""A structure's energy and its ledger, from its modal state: a mixin of
:class:`cosim.sides.fem.StructureSubsystem`, which holds the modes'
frequencies ``omega``, damping ``modal_damping``, the modal load of gravity
``_g_modal`` and the ledger in ``aux``."""
from __future__ import annotations

import numpy as np

__all__ = ["StructureEnergy"]


class StructureEnergy:
    """The energy face of :class:`cosim.sides.fem.StructureSubsystem`."""

    def energy(self, x=None):
        x = self.x if x is None else x
        m = self.n_modes
        q, dq = x[:m], x[m:2 * m]
        return 0.5 * float(dq @ dq + (self.omega * q) @ (self.omega * q)) \
            - float(self._g_modal @ q)

    def energies(self, X):
        """:meth:`energy` at each row of the states ``X`` (m, n_states), on
        arrays (the sums taken in another order: equal to round-off)."""
        X = np.asarray(X, float)
        m = self.n_modes
        q, dq = X[:, :m], X[:, m:2 * m]
        wq = self.omega * q
        return 0.5 * (np.einsum("ij,ij->i", dq, dq) + np.einsum("ij,ij->i", wq, wq)) \
            - q @ self._g_modal

    def ledger(self):
        return float(self.aux[-2]), 0.0

    def ledger_rates(self, t, x):
        m = self.n_modes
        dq = x[m:2 * m]
        return float(self.modal_damping @ (dq * dq)), 0.0
