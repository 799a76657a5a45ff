"""The face the compiled macro loop (:mod:`cosim.core.schemes._driver`) steps
a side through: the members the ``compiled_loop`` capability promises
(``CAPABILITIES`` in :mod:`cosim.core.subsystem`), so that the loop reads
and writes nothing private of a side.

A side's own step stays private (``_step_impl``, ``_compiled_step``); this
mixin names, for the loop, what it may ask and set:

- :meth:`compiled_step`: the compiled kernel that takes a step, or None;
- :meth:`reference_step`: the side's own step (its reference), without the
  template's bookkeeping, which the loop keeps itself;
- :meth:`begin_step`: the step's start and length, which the embedded
  contacts' quadratures are measured from, set before the kernel steps;
- :attr:`embedded_contacts`: the contacts embedded in the side (the live
  list, in slot order);
- :attr:`switch_handler`: what the kernel calls at each located switch;
- :attr:`closed_end`: per hosted contact, closed (1) or open (0) at the end
  of the last step (the array the kernel writes in place), or None for a
  side that keeps no such record (a multibody side);
- :meth:`loop_kernel`: the kernel whose C face (``side_face()``, see
  :mod:`cosim.core._side_face`) may take the side's steps with no Python
  call, or None.  A class whose kernel mirrors its Python step says so
  (``loop_face_faithful = True`` in its body); the methods the face stands
  in for (``FACE_MIRRORS``) are noted then, and a side where any was
  replaced since (a subclass, an instance's own, a test's patch) offers no
  face: the loop takes its Python methods.
"""
from __future__ import annotations

__all__ = ["LoopFace", "FACE_MIRRORS"]

#: the side's methods that its C face stands in for in the compiled loop
FACE_MIRRORS = ("outputs", "_step_impl", "_compiled_step", "compiled_step", "reference_step",
                "begin_step", "_on_switch")


class LoopFace:
    """Mixin of the sides that declare ``compiled_loop``: the compiled loop's
    public face of a side (see the module's docstring)."""

    #: no record of closed ends unless a side keeps one (a structure)
    _closed_end = None
    #: no contact embedded unless a side embeds one
    _embedded: tuple = ()
    #: no switch to hear of unless a side locates them
    _on_switch = None

    #: the methods FACE_MIRRORS names, as the class that declared
    #: ``loop_face_faithful`` defined them; None where no class did
    _face_methods = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("loop_face_faithful", False):
            cls._face_methods = {n: getattr(cls, n, None) for n in FACE_MIRRORS}

    def _compiled_step(self, inputs):
        return None

    def loop_kernel(self, inputs):
        """The compiled kernel whose C face may take this side's steps in the
        compiled loop with no Python call (asked again when its face's
        ``generation`` changes), or None: the side's class does not declare
        its kernel faithful, or one of ``FACE_MIRRORS`` was replaced, or
        :meth:`compiled_step` gives none for ``inputs``."""
        return self.compiled_step(inputs) if self._face_faithful() else None

    def _face_faithful(self) -> bool:
        """Whether this side's class declares its kernel's C face faithful
        and none of ``FACE_MIRRORS`` was replaced since."""
        known = self._face_methods
        own = getattr(self, "__dict__", {})
        return not (known is None or any(n in own for n in FACE_MIRRORS) or any(
            getattr(type(self), n, None) is not f for n, f in known.items()))

    def compiled_step(self, inputs):
        """The compiled kernel that takes the step under ``inputs`` (a
        :class:`~cosim.core.subsystem.StepInput`), or None where the side's
        own step (:meth:`reference_step`) must take it."""
        return self._compiled_step(inputs)

    def reference_step(self, t: float, h: float, inputs) -> None:
        """The side's own step over ``[t, t + h]`` (its reference), leaving
        ``t`` and ``n_steps`` to the caller."""
        self._step_impl(t, h, inputs)

    def begin_step(self, t: float, h: float) -> None:
        """Start a step of length ``h`` [s] at ``t`` [s]: the time the
        embedded contacts' first moments are taken from."""
        self._t0, self._h = t, h

    @property
    def embedded_contacts(self):
        """The contacts embedded in this side, in slot order (the live list)."""
        return self._embedded

    @property
    def switch_handler(self):
        """``handler(t, slot, on, y)``, told of each switch the kernel locates,
        or None."""
        return self._on_switch

    @property
    def closed_end(self):
        """Per hosted contact, closed (1) or open (0) at the end of the last
        step, -1 before the first (an int8 array written in place), or None."""
        return self._closed_end
