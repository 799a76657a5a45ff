"""The boundary between cosim and the plug-ins it loaded
(:mod:`cosim.core.plugins`): what a plug-in raised or returned, blamed on
the plug-in, never on cosim or the scene.

A plug-in's class is recorded here when it is loaded, with the
distribution and entry point that declare it.  Its code is then judged
where cosim meets it, not on every step:

- a contact law's outputs once, when the scene builds it
  (:func:`check_law`: every method cosim calls, on a few states, must
  return finite real numbers of the input's shape, its stiffness and
  damping ``>= 0`` or NaN);
- a structure's ``dof_bound()`` and ``assemble()`` when called
  (:func:`call`, :func:`refuse`), an integrator's state after its step
  (the subsystem checks the shape, in one comparison per step);
- anything else a plug-in raises, at any time, by the traceback of the
  exception (:func:`blame`): the innermost frame that is not a library's
  decides, the plug-in's own code or cosim's code run on a plug-in's
  object (a method it inherits).

Each such failure is a :class:`~cosim.errors.PluginError` whose message
names the distribution and the entry point and says what the plug-in
returned or raised; the command line exits with status 2.  Classes
registered from Python (``CONTACT_LAWS["name"] = cls``) are the caller's
own code and are not judged here.
"""
from __future__ import annotations

import numbers

import numpy as np

from cosim.errors import PluginError, shown

__all__ = ["loaded", "origin_of", "blame", "call", "refuse", "check_law"]

#: plug-in class -> "distribution `D` 1.0, entry point `N = m:C` in group `G`"
_ORIGINS: dict = {}
#: top-level package of each plug-in's module -> the origin of its (first) class
_PACKAGES: dict = {}
#: cosim's own packages: their frames are judged by the object they run on
_OURS = ("cosim", "couplers", "fem", "multibody")


def loaded(cls, origin: str) -> None:
    """Record plug-in class ``cls``, loaded from ``origin``."""
    _ORIGINS[cls] = origin
    _PACKAGES.setdefault(cls.__module__.split(".")[0], origin)


def origin_of(obj) -> str | None:
    """The origin of a plug-in's class or instance, or None for cosim's own
    (and a class registered from Python)."""
    if not _ORIGINS:
        return None
    cls = obj if isinstance(obj, type) else type(obj)
    for klass in cls.__mro__:
        if klass in _ORIGINS:
            return _ORIGINS[klass]
    return None


def refuse(obj, what: str, returned, expected: str) -> PluginError:
    """The error of plug-in ``obj`` whose ``what`` (``assemble()``) returned
    ``returned`` where cosim expected ``expected``."""
    if isinstance(returned, (np.ndarray, np.generic)) and np.ndim(returned) == 0:
        returned = returned.item()                 # a number numpy gave
    got = (shown(repr(returned)) if isinstance(returned, str) else
           shown(returned) if isinstance(returned, numbers.Number) or returned is None else
           _described(returned))
    return PluginError(f"the plug-in {origin_of(obj)}: its {what} returned {got}, expected "
                       f"{expected}")


def call(obj, method: str, *args):
    """``obj.method(*args)``, whatever the plug-in raises in it (Ctrl-C
    aside) a :class:`PluginError` naming it."""
    try:
        return getattr(obj, method)(*args)
    except KeyboardInterrupt:
        raise
    except BaseException as exc:
        raise PluginError(f"the plug-in {origin_of(obj)}: its {method}() raised "
                          f"{_what(exc)}") from None


def _what(exc: BaseException) -> str:
    """``TypeError: its text``, or the type alone when it has no text."""
    text = shown(str(exc))
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def blame(exc: BaseException) -> PluginError | None:
    """``exc`` as the failure of the plug-in it comes from, or None when it
    is not a plug-in's.

    The frames of its traceback are read from the innermost out, skipping
    those of libraries (numpy, the standard library): a frame of a plug-in's
    package blames that plug-in; a frame of cosim's own code blames the
    plug-in whose object it runs on (``self``, a method the class inherits),
    and else ends the search: cosim's own failure.
    """
    if isinstance(exc, PluginError) or not _ORIGINS:
        return exc if isinstance(exc, PluginError) else None
    frames = []
    tb = exc.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    for frame in reversed(frames):
        top = str(frame.f_globals.get("__name__", "")).split(".")[0]
        where = f"{frame.f_code.co_name}()"
        if top in _PACKAGES:          # its own code: its class's origin, else its package's
            origin = origin_of(frame.f_locals.get("self")) or _PACKAGES[top]
            how = f"raised {_what(exc)}, in its {where}"
        elif top in _OURS:
            origin = origin_of(frame.f_locals.get("self"))
            if origin is None:
                return None
            how = (f"made cosim's {where}, which its class inherits, raise {_what(exc)}, "
                   f"on what its own methods returned")
        else:
            continue
        err = PluginError(f"the plug-in {origin}: {how}")
        err.partial_result = getattr(exc, "partial_result", None)
        return err
    return None


def _described(value) -> str:
    """A returned value in a few words: an array's shape and dtype, a
    sequence's length and first entries, another object's type and repr."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    if isinstance(value, (tuple, list)):
        return f"a {type(value).__name__} of {len(value)}: {shown(value, 80)}"
    return f"{type(value).__name__} {shown(value, 80)}"


#: the states a law is asked about when it is built: penetrations [m] and rates [m/s]
_PENETRATIONS = (-1e-4, 0.0, 1e-9, 1e-6, 1e-4)
_RATES = (-1.0, 0.0, 1.0)


def _bad_number(value, shape: tuple) -> str:
    """Why ``value`` is not finite real numbers of ``shape`` (or a scalar),
    or ``""``."""
    if isinstance(value, (str, bytes)) or value is None:
        return "a string" if isinstance(value, (str, bytes)) else "None"
    try:
        arr = np.asarray(value)
    except Exception:                       # a plug-in's object numpy cannot read
        return "not a number"
    if arr.dtype.kind not in "iuf":
        return f"of dtype {arr.dtype}"
    if arr.shape not in ((), shape):
        return f"of shape {arr.shape}"
    if not np.all(np.isfinite(arr)):
        return "not finite"
    return ""


def check_law(law) -> None:
    """Judge plug-in law ``law`` once, as its scene builds it: each method
    cosim calls, on scalars and on an array of a few states
    (:data:`_PENETRATIONS`, :data:`_RATES`), returns finite real numbers,
    a scalar or the input's shape; ``evaluate`` three of them; its
    ``stiffness`` and ``damping`` are real numbers ``>= 0``, or NaN (none).

    Raises
    ------
    PluginError
        Naming the plug-in, the method, the state and what it returned.
    """
    if origin_of(law) is None:
        return
    for attr in ("stiffness", "damping"):
        try:
            v = getattr(law, attr)
        except KeyboardInterrupt:
            raise
        except BaseException as exc:
            raise PluginError(f"the plug-in {origin_of(law)}: its `{attr}` raised "
                              f"{_what(exc)}") from None
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real) or v < 0:
            unit = "N/m" if attr == "stiffness" else "N s/m"
            raise refuse(law, f"`{attr}`", v, f"a real number >= 0 [{unit}], inf for a rigid "
                                              f"law, or NaN for none")
    d = np.repeat(np.asarray(_PENETRATIONS), len(_RATES))
    dd = np.tile(np.asarray(_RATES), len(_PENETRATIONS))
    states = [(float(a), float(b)) for a, b in zip(d, dd)] + [(d, dd)]
    if law.rigid:                              # resolved by impulses: its switch alone
        methods = (("switch", lambda x, v: (x, v)),)
    else:
        methods = (("force_active", lambda x, v: (x, v)), ("force", lambda x, v: (x, v)),
                   ("switch", lambda x, v: (x, v)), ("potential", lambda x, v: (x,)),
                   ("potential_slope", lambda x, v: (x,)),
                   ("dissipation_rate", lambda x, v: (np.zeros_like(x) + 1.0, x, v)))
    for x, v in states:
        shape = np.shape(x)
        for method, args in methods:
            out = call(law, method, *args(x, v))
            why = _bad_number(out, shape)
            if why:
                at = (f"d = {x!r} m, dd = {v!r} m/s" if not shape else
                      f"arrays of {shape[0]} states (d in [{_PENETRATIONS[0]}, "
                      f"{_PENETRATIONS[-1]}] m)")
                want = ("a finite real number" if not shape else
                        f"finite real numbers, a scalar or an array of shape {shape}")
                raise refuse(law, f"{method}() at {at}", out, f"{want} (it is {why})")
        if not shape and not law.rigid:
            out = call(law, "evaluate", x, v)
            if not (isinstance(out, tuple) and len(out) == 3
                    and not any(_bad_number(o, ()) for o in out)):
                raise refuse(law, f"evaluate() at d = {x!r} m, dd = {v!r} m/s", out,
                             "a tuple of three finite floats (force, dissipated power, "
                             "switch)")


def bad_state(integ, y1, shape) -> None:
    """Refuse the state ``y1`` that integrator ``integ`` returned, not of ``shape``."""
    import numpy as np

    if origin_of(integ) is not None:
        raise refuse(integ, "integrate()", y1, f"the state, an array of shape {shape}")
    raise ValueError(f"integrator `{integ.name}` returned a state of shape {np.shape(y1)}, "
                     f"expected {shape}")
