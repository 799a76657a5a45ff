"""Implicit co-simulation: repeat the macro step until the forces agree."""
from __future__ import annotations

import math
import warnings
from typing import ClassVar

import numpy as np

from couplers.linear_laws import KelvinVoigtLaw, LinearLaw

from cosim.core.hermite import hermite_coefficients
from cosim.core.subsystem import RigidReference
from .base import RELATIVE_RULE, CoSimulationScheme, CouplingError, Option, _pos, _relative

__all__ = ["Implicit", "Aitken", "IQNILS", "ACCELERATIONS"]

#: relative round-off floor of the interface unknowns (in units of the
#: machine epsilon): a residual this close to them is as converged as the
#: arithmetic allows
_ROUNDOFF = 64 * np.finfo(float).eps


class Aitken:
    """Relaxation ``x + omega r`` with Aitken's dynamic factor.

    ``omega`` starts at ``relaxation`` in every macro step and is updated
    from two successive residuals, ``omega_k = -omega_{k-1} r_{k-1}.dr / dr.dr``
    (Irons and Tuck 1969; Kuettler and Wall 2008, eq. 44).  One scalar for
    all contacts: it is the secant method when there is one.

    Parameters
    ----------
    relaxation : float
        Factor of the first iteration of each step, in (0, 1].
    """

    name: ClassVar[str] = "aitken"

    def __init__(self, relaxation: float, **_):
        self.relaxation = relaxation

    def start(self, key) -> None:
        """Begin a macro step (``key`` is ignored: nothing is kept)."""
        self._omega = self.relaxation
        self._r_prev = None

    def update(self, x: np.ndarray, hx: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Next guess from the guess ``x``, its image ``hx = H(x)`` and the
        residual ``r = hx - x``."""
        if self._r_prev is not None:
            dr = r - self._r_prev
            denom = float(dr @ dr)
            if denom > 0:
                self._omega = -self._omega * float(self._r_prev @ dr) / denom
        self._r_prev = r
        return x + self._omega * r

    def finish(self) -> None:
        """The macro step converged."""


class IQNILS:
    """Interface quasi-Newton with an inverse Jacobian from a least-squares
    model (IQN-ILS).

    For the fixed-point operator ``H`` (guessed end-of-step coupler forces to
    the forces the law gives on the resulting outputs) with residual
    ``r = H(x) - x``, the columns of ``V`` are differences of successive
    residuals and those of ``W`` the matching differences of ``H``.  The
    next guess is ``H(x_k) + W alpha`` with ``alpha`` the least-squares
    solution of ``V alpha = -r_k`` (Degroote et al. 2009), found by an
    economy QR factorisation of ``V``.  Without a column (the first
    iteration of a step, unless columns are reused) the guess is relaxed by
    the constant ``relaxation``.

    Columns are ordered newest first.  Before each solve, columns whose part
    orthogonal to the newer ones is below ``filter_tolerance`` times their
    norm are dropped (filter QR2 of Haelterman et al. 2016), and at most as
    many columns as there are coupler contacts are kept: more are linearly
    dependent.

    ``reuse`` keeps the columns of that many previous converged macro
    steps.  They are dropped whole when the step length changes or when
    the set of closed coupler contacts differs from that of the step they
    came from: the interface Jacobian of a penalty law jumps when a contact
    opens or closes and scales with the step.

    Parameters
    ----------
    relaxation : float
        Constant relaxation of an iteration without columns, in (0, 1].
    reuse : int
        Number of previous macro steps whose columns are kept, >= 0.
    filter_tolerance : float
        Relative QR-filter threshold, > 0.

    References
    ----------
    J. Degroote, K.-J. Bathe and J. Vierendeels, "Performance of a new
    partitioned procedure versus a monolithic procedure in fluid-structure
    interaction", Computers & Structures 87 (2009) 793-801.

    R. Haelterman, A. Bogaers, K. Scheufele, B. Uekermann and M. Mehl,
    "Improving the performance of the partitioned QN-ILS procedure for
    fluid-structure interaction problems: filtering", Computers & Structures
    171 (2016) 9-17.
    """

    name: ClassVar[str] = "iqn_ils"

    def __init__(self, relaxation: float, reuse: int = 0, filter_tolerance: float = 1e-6):
        self.relaxation = relaxation
        self.reuse = reuse
        self.filter_tolerance = filter_tolerance
        self._old: list[tuple[np.ndarray, np.ndarray]] = []   # (V, W) per step, newest first
        self._key = None

    def start(self, key) -> None:
        """Begin a macro step; ``key`` (step length [s], closed contacts)
        decides whether the columns of earlier steps still apply."""
        h, closed = key
        if self._key is None or not (math.isclose(h, self._key[0], rel_tol=1e-9)
                                     and closed == self._key[1]):
            self._old = []
        self._key = key
        self._V: list[np.ndarray] = []
        self._W: list[np.ndarray] = []
        self._r_prev = self._hx_prev = None

    def update(self, x: np.ndarray, hx: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Next guess from the guess ``x``, its image ``hx = H(x)`` and the
        residual ``r = hx - x``."""
        if self._r_prev is not None:
            self._V.insert(0, r - self._r_prev)
            self._W.insert(0, hx - self._hx_prev)
        self._r_prev, self._hx_prev = r, hx
        V, W = self._columns(len(r))
        if V is None:
            return x + self.relaxation * r
        Q, R = np.linalg.qr(V)
        alpha = np.linalg.solve(R, -(Q.T @ r))
        return hx + W @ alpha

    def finish(self) -> None:
        """The macro step converged: keep its columns for the next steps."""
        if self.reuse and self._V:
            block = (np.column_stack(self._V), np.column_stack(self._W))
            self._old = ([block] + self._old)[:self.reuse]

    def _columns(self, n: int):
        """``V`` and ``W`` after the QR filter, at most ``n`` columns; None if
        no column is left."""
        blocks_v = ([np.column_stack(self._V)] if self._V else []) + [v for v, _ in self._old]
        blocks_w = ([np.column_stack(self._W)] if self._W else []) + [w for _, w in self._old]
        if not blocks_v:
            return None, None
        V, W = np.hstack(blocks_v), np.hstack(blocks_w)
        while V.shape[1]:
            head = V[:, :n]
            R = np.linalg.qr(head, mode="r")
            norms = np.linalg.norm(head, axis=0)
            # not (>=) also drops non-finite columns, and norms == 0 zero
            # ones (a residual repeated exactly), which 0 >= 0 would keep
            bad = np.flatnonzero(~(np.abs(np.diag(R)) >= self.filter_tolerance * norms)
                                 | (norms == 0))
            if not bad.size:
                break
            V, W = np.delete(V, bad[0], axis=1), np.delete(W, bad[0], axis=1)
        if not V.shape[1]:
            return None, None
        return V[:, :n], W[:, :n]


#: name -> acceleration of the implicit scheme's fixed-point iteration
ACCELERATIONS: dict[str, type] = {cls.name: cls for cls in (Aitken, IQNILS)}


class Implicit(CoSimulationScheme):
    """Fixed-point iteration on the contact forces at the step's end.

    Each pass restores the saved states, steps every subsystem with the
    force interpolated linearly from ``f(t)`` to the current guess of
    ``f(t + h)``, and evaluates the law on the new outputs: that is the
    fixed-point operator ``H(guess)``.  The iteration stops when every
    coupler contact's residual ``H(guess) - guess`` is within
    ``force_tolerance + tolerance * |force|``.  The predictor is the force
    extrapolated at ``extrapolation_order``.

    The next guess comes from ``acceleration``:

    ``"aitken"`` (default)
        Relaxation with Aitken's dynamic factor (Irons and Tuck 1969;
        Kuettler and Wall 2008, eq. 44), one scalar for all contacts.
    ``"iqn_ils"``
        Interface quasi-Newton, inverse Jacobian from a least-squares model
        of past secants (Degroote et al. 2009), with a QR filter
        (``filter_tolerance``, Haelterman et al. 2016) and the secants of
        ``reuse`` earlier steps.  See :class:`IQNILS`.

    With a single coupler contact both are the secant method.  With several
    contacts of different stiffness or mobility at once, Aitken's single
    factor cannot suit every direction of the residual, while IQN-ILS
    learns one per direction.

    References
    ----------
    B. M. Irons and R. C. Tuck, "A version of the Aitken accelerator for
    computer iteration", Int. J. Numer. Meth. Engng 1 (1969) 275-277.

    U. Kuettler and W. A. Wall, "Fixed-point fluid-structure interaction
    solvers with dynamic relaxation", Comput. Mech. 43 (2008) 61-72.

    J. Degroote, K.-J. Bathe and J. Vierendeels, "Performance of a new
    partitioned procedure versus a monolithic procedure in fluid-structure
    interaction", Computers & Structures 87 (2009) 793-801.

    R. Haelterman et al., "Improving the performance of the partitioned
    QN-ILS procedure for fluid-structure interaction problems: filtering",
    Computers & Structures 171 (2016) 9-17.
    """

    name: ClassVar[str] = "implicit"
    explicit: ClassVar[bool] = False
    options: ClassVar[dict] = {
        **CoSimulationScheme.options,
        "extrapolation_order": Option(int, 1, lambda v: v in (0, 1, 2), "0, 1 or 2"),
        "max_iterations": Option(int, 50, lambda v: v >= 1, ">= 1"),
        "tolerance": Option(float, 1e-8, _relative, RELATIVE_RULE),
        "force_tolerance": Option(float, 1e-9, _pos, "> 0 N"),
        "relaxation": Option(float, 0.5, lambda v: 0 < v <= 1, "in (0, 1]"),
        "acceleration": Option(str, "aitken", lambda v: v in ACCELERATIONS,
                               f"one of {sorted(ACCELERATIONS)}"),
        "reuse": Option(int, 0, lambda v: v >= 0, ">= 0 (macro steps)"),
        # Relative: a column is dropped when the sine of its angle to the
        # newer columns is below this.  Near convergence a residual
        # difference is known only to about 1e-8 of itself (it is a
        # difference of forces converged to `tolerance` 1e-8), so an
        # independent part much below that is noise; 1e-6 keeps the
        # least-squares solve well away from it.
        "filter_tolerance": Option(float, 1e-6, lambda v: _pos(v) and v < 1, "in (0, 1)"),
    }

    #: options that only IQN-ILS reads
    _IQN_OPTIONS: ClassVar[tuple] = ("reuse", "filter_tolerance")

    #: iterate in compiled code (:mod:`cosim.core.schemes._implicit_step`)
    #: where the system allows it (:meth:`_compiled_iterations`); False makes
    #: the Python reference iterate whatever the system (the tests compare
    #: the two)
    compiled_iterations: ClassVar[bool] = True
    _kernel = None

    def __init__(self, **opts):
        super().__init__(**opts)
        ignored = sorted(k for k in self._IQN_OPTIONS if k in opts)
        if ignored and self.acceleration != "iqn_ils":
            warnings.warn(f"scheme `implicit` with `acceleration` {self.acceleration!r} "
                          f"ignores the options {ignored}", stacklevel=2)

    def run(self, system, t_end, recorder):
        kw = {"relaxation": self.relaxation}
        if self.acceleration == "iqn_ils":
            kw.update({k: getattr(self, k) for k in self._IQN_OPTIONS})
        self._accel = ACCELERATIONS[self.acceleration](**kw)
        built = self.__dict__.pop("_prepared", None)      # by prepare(), for this system
        self._kernel = (built[1] if built is not None and built[0] is system else
                        self._compiled_iterations(system) if self.compiled_iterations else None)
        return super().run(system, t_end, recorder)

    def prepare(self, system, t_end, recorder):
        # the sides' kernels, the compiled iterations over them and the
        # modules of the run's loop, before the clock (the run takes them)
        super().prepare(system, t_end, recorder)
        from cosim.core.schemes import implicit_block
        self._prepared = (system, implicit_block.prepare(self, system, recorder))

    def _macro_blocks(self, system, recorder, books, t_end, n, H, sliver, controlled, h_prev):
        """:mod:`cosim.core.schemes.implicit_block`'s loop where it covers the
        run; None where the Python loop runs (:attr:`loop_refusal` says why)."""
        from cosim.core.schemes import implicit_block
        self.loop_refusal = implicit_block.refusal(self, system, recorder, controlled)
        if self.loop_refusal is not None:
            return None
        return implicit_block.run_blocks(self, system, recorder, books, self._state, t_end, n,
                                         H, sliver, h_prev)

    # ------------------------------------------------- compiled iterations
    def _compiled_iterations(self, system):
        """The compiled iterations of this system
        (:class:`cosim.core.schemes._implicit_step.ImplicitStep`), or None
        where the Python reference iterates: the kernel not built, a contact
        hosted by a moving side or following a point, a moving side that
        offers no compiled step without Python (``compiled_side``: the numpy
        reference chosen, a contact embedded in it, another integrator), a
        rigid side other than :class:`RigidReference`, or a coupler contact
        whose law is not linear or Kelvin-Voigt, or with friction."""
        if system.hosted or system.followers or not len(system.coupler_rows):
            return None
        from cosim.core.kernel_import import import_kernel
        try:
            _implicit_step = import_kernel("cosim.core.schemes._implicit_step")
        except ImportError:             # not built: the reference iterates
            return None
        cs = system.connections
        if cs is not None and cs.mode.dtype != np.int64:
            return None
        contacts = []
        row_a, row_b = system.contact_rows
        normals, offsets = system.contact_normals, system.contact_offsets
        maps = system.exchange_maps
        for c in system.coupler:
            ln = system.links[c]
            law, conn = ln.contact.law, ln.connection
            if type(law) not in (LinearLaw, KelvinVoigtLaw) or (
                    conn is not None and conn.friction is not None):
                return None
            g = None if conn is None else conn.grasp
            contacts.append((int(c), int(row_a[c]), int(row_b[c]), normals[c], offsets[c],
                             _implicit_step.LAW_KINDS[law.name], law.contact_stiffness,
                             getattr(law, "contact_damping", 0.0), int(system.tangent_row[c]),
                             None if g is None else (g.stiffness, g.damping,
                                                     g.tangential_stiffness,
                                                     g.tangential_damping)))
        first = np.cumsum([0] + [sub.n_ports for sub in system.subsystems])
        sides, moving = [], self._moving(system)
        for s, sub in enumerate(system.subsystems):
            if s not in moving:
                if type(sub) is not RigidReference:
                    return None
                continue
            get = getattr(sub, "compiled_side", None)
            kernel = None if get is None else get()
            if not hasattr(kernel, "side_face"):    # none, or built before the C face
                return None
            sides.append((kernel, sub.x, sub.aux, maps[s], int(first[s])))
        outs = system.outputs()
        opts = {"max_iterations": self.max_iterations, "tolerance": self.tolerance,
                "force_tolerance": self.force_tolerance, "acceleration": self.acceleration,
                "relaxation": self.relaxation, "reuse": self.reuse,
                "filter_tolerance": self.filter_tolerance, "roundoff": _ROUNDOFF}
        self._kernel_sides = list(moving)
        return _implicit_step.ImplicitStep(
            sides, np.concatenate([o[0] for o in outs]), np.concatenate([o[1] for o in outs]),
            contacts, system.coupler_rows, system.n_rows,
            None if cs is None else cs.mode, None if cs is None else cs.anchor, opts)

    def _advance_compiled(self, system, t, h, ratio):
        """:meth:`advance` by the compiled iterations: one call."""
        kernel, f_n = self._kernel, self._f
        try:
            it, converged, guess, stepped, coeffs, moments = kernel.advance(
                t, h, f_n, self._extrapolated(ratio))
        except Exception:
            if kernel.failed_side >= 0:     # as Subsystem.step marks a side whose step raised
                system.subsystems[self._kernel_sides[kernel.failed_side]].status = "failed"
            raise
        for s, pm in zip(self._kernel_sides, moments):
            system.subsystems[s].took_compiled_step(t, h, pm)
            system.book_applied(s, coeffs)      # as step_input keeps them
        self.n_iterations += it
        if converged:
            return stepped
        return self._not_converged(system, t, h, f_n, guess, kernel.residual,
                                   system.coupler_rows, [])

    def advance(self, system, t, h, ratio):
        if self._kernel is not None:
            return self._advance_compiled(system, t, h, ratio)
        coupler = system.coupler_rows      # normal and tangential rows exchanged
        hosted = list(system.hosted)
        hosts = {system.hosted[c].host for c in hosted}
        # hosts step first in each pass, so their partners get this pass's force
        moving = sorted(self._moving(system), key=lambda s: s not in hosts)
        f_n = self._f
        guess = np.sum(self._extrapolated(ratio), axis=0)
        saved = system.get_state()
        imp0 = self._hosted_impulses(system)
        motion = self._motion_guess(system, hosted, t, h)
        accel = self._accel
        accel.start((h, tuple(f_n[coupler] > 0)))
        nh = len(hosted)
        for it in range(1, self.max_iterations + 1):
            if it > 1:
                system.set_state(saved)
            coeffs = np.stack([f_n, guess - f_n])
            after = {}
            for c, (x1, v1) in zip(hosted, motion):
                self._set_hermite(system, c, t, h, x1, v1)
            for s in moving:
                cf = coeffs
                for c in hosted:
                    host, _, partner, _, _ = system.hosted[c]
                    if partner == s and host in after:
                        cf = cf.copy() if cf is coeffs else cf
                        cf[:, c] = system.hosted_force(c, h, imp0[c])
                sub = system.subsystems[s]
                sub.step(t, h, system.step_input(s, t, h, cf))
                after[s] = sub.outputs(sub.t, sub.x)
            if not len(coupler) and not nh:
                self.n_iterations += it
                return h * (f_n + 0.5 * (guess - f_n))
            outs = system.outputs()
            d, dd = system.penetrations(outs)
            f_new = system.forces(d, dd)
            # unknowns in newtons: coupler forces, then k times each hosted
            # partner's end position and h times its end velocity
            k = np.array([system.links[c].contact.law.stiffness for c in hosted])
            actual = [self._partner_end(system, c, outs) for c in hosted]
            z = np.concatenate([guess[coupler], self._scaled(motion, k, h)])
            hz = np.concatenate([f_new[coupler], self._scaled(actual, k, h)])
            r = hz - z
            for i, c in enumerate(hosted):  # no force, the partner's end short of the contact:
                host, slot = system.embedded[c]  # the motion is moot (past it, the touch is in)
                if system.subsystems[host].embedded_quadratures()[slot, 0] == imp0[c] \
                        and d[c] <= 0:
                    r[len(coupler) + 4 * i:len(coupler) + 4 * i + 4] = 0.0
            view = np.abs(list(system.hosted_view_forces(outs).values()))
            scale = np.concatenate([np.maximum(np.abs(f_new[coupler]), np.abs(guess[coupler])),
                                    np.repeat(view, 4)])
            # a hosted partner's unknowns are stiffness times position: with
            # the contact open at the step's end (no view force) their
            # residual cannot fall below the round-off of the unknowns
            floor = _ROUNDOFF * np.maximum(np.abs(z), np.abs(hz))
            if np.all(np.abs(r) <= self.force_tolerance + self.tolerance * scale + floor):
                self.n_iterations += it
                accel.finish()
                return h * (f_n + 0.5 * (guess - f_n))
            z = accel.update(z, hz, r)
            nc = len(coupler)
            guess = guess.copy()
            guess[coupler] = z[:nc]
            motion = self._unscaled(z[nc:], k, h)
        self.n_iterations += self.max_iterations
        return self._not_converged(system, t, h, f_n, guess, r, coupler, hosted)

    def _not_converged(self, system, t, h, f_n, guess, r, coupler, hosted):
        """The step did not converge: retried shorter (flagged for the macro
        loop) where a long step may be, a :class:`CouplingError` otherwise."""
        if self.contact_step is not None and (h > self.contact_step * (1 + 1e-9)
                                              or self._state.aimed):
            # (a step landed on an onset may end just past it, with no fixed
            # point either: it is retried shorter too)
            # a long step over a contact that touches and leaves inside it (a
            # vibrating side): no fixed point to find; the step is retried shorter
            self._unconverged = True
            return h * (f_n + 0.5 * (guess - f_n))
        nc = len(coupler)
        worst = np.concatenate([np.abs(r[:nc]), np.abs(r[nc:]).reshape(-1, 4).max(axis=1)])
        i = int(np.argmax(worst))
        if i < nc:
            what = (f"contact `{system.row_names[coupler[i]]}` has a force residual of "
                    f"{worst[i]:.3g} N")
        else:
            c = hosted[i - nc]
            what = (f"contact `{system.contact_names[c]}` (hosted by "
                    f"`{system.names[system.hosted[c].host]}`): its partner's motion has a "
                    f"residual of {worst[i]:.3g} N (stiffness times position, or times "
                    f"step times velocity)")
        raise CouplingError(
            f"implicit coupling did not converge at t = {t:.6g} s (step {h:.3g} s) within "
            f"{self.max_iterations} iterations: {what}. Reduce "
            f"`scheme.{'contact_step' if self.contact_step else 'macro_step'}` or raise "
            f"`scheme.max_iterations`.")

    # ------------------------------------------------------ hosted contacts
    def _motion_guess(self, system, hosted, t, h):
        """First guess of each hosted partner's port position and velocity at
        ``t + h``: extrapolated as the explicit schemes do."""
        out = []
        for c in hosted:
            self._set_partner_motion(system, c, t, h)
            out.append(system.hosted[c].embedded.partner(t + h))
        return out

    def _set_hermite(self, system, c, t, h, x1, v1):
        _, _, partner, port, emb = system.hosted[c]
        pos, vel = self._outs[partner]
        x0, v0 = complex(*pos[port]), complex(*vel[port])
        emb.set_motion(t, h, hermite_coefficients(x0, v0, x1, v1, h))

    @staticmethod
    def _partner_end(system, c, outs):
        _, _, partner, port, _ = system.hosted[c]
        pos, vel = outs[partner]
        return complex(*pos[port]), complex(*vel[port])

    @staticmethod
    def _scaled(motion, k, h):
        if not motion:
            return np.zeros(0)
        m = np.array(motion)                        # (n, 2) complex: x1, v1
        return (k[:, None] * np.stack([m[:, 0].real, m[:, 0].imag, h * m[:, 1].real,
                                       h * m[:, 1].imag], axis=1)).ravel()

    @staticmethod
    def _unscaled(z, k, h):
        z = z.reshape(-1, 4) / k[:, None]
        return [(complex(a, b), complex(c, d) / h) for a, b, c, d in z]
