"""Embedded explicit Runge-Kutta pairs with dense output and event location.

:func:`solve` integrates ``y' = f(t, y)`` from ``t0`` to ``t1`` with the
Dormand-Prince 5(4) pair (``"RK45"``) or the Dormand-Prince 8(5,3) pair
(``"DOP853"``), whose coefficients :mod:`cosim.core.rk_tableaux` holds with
their sources.  Numpy only: importing this module costs next to nothing, where
``scipy.integrate`` costs about half a second.

The algorithm is the textbook one (Hairer, Norsett & Wanner, *Solving
Ordinary Differential Equations I*, sec. II.4 for the starting step, II.5 for
the pairs and the error control, II.6 for dense output):

- error norm: the root mean square of the local error estimate, each
  component scaled by ``atol + rtol max(|y_n|, |y_n+1|)``; for DOP853 the
  5th-order estimate damped by the 3rd-order one as in the published code;
- step-size control: ``h_new = h min(fac_max, max(fac_min, 0.9 err^(-1/(q+1))))``
  with ``q`` the estimate's order, ``fac_max`` held at 1 right after a
  rejected step; ``max_step`` bounds every step and the last lands on ``t1``;
- events: components of a vector function ``g(t, y)`` whose sign change over
  an accepted step, in the requested direction, is located on the step's
  dense output by a safeguarded Illinois (modified regula falsi) iteration;
  a terminal one ends the integration there.
"""
from __future__ import annotations

import math
import numpy as np

from cosim.core import rk_tableaux

__all__ = ["Pair", "PAIRS", "Events", "Result", "solve", "single_step", "locate_root"]

_EPS = np.finfo(float).eps
_TINY = np.finfo(float).tiny
SAFETY = 0.9


def _rows(spec: dict, n: int) -> np.ndarray:
    """Sparse rows ``{index: value}`` -> a dense ``(len, n)`` array."""
    out = np.zeros((len(spec), n))
    for i, row in enumerate(spec):
        for j, v in row.items():
            out[i, j] = v
    return out


class Pair:
    """An embedded pair: its tableau as dense arrays.

    Attributes
    ----------
    name : str
    order : int
        Order of the solution carried on.
    error_order : int
        Order of the error estimate (the step controller's exponent is
        ``-1 / (error_order + 1)``).
    stages : int
        Stages that make the solution; stage ``stages`` is the slope at its
        end (first same as last).
    c, a : arrays
        Nodes and the coefficient matrix of every stage, the dense output's
        extra stages included.
    b : (stages,) array
        Weights of the solution.
    e, e3 : arrays
        Weights of the error estimate(s) over the first ``stages + 1`` stages
        (``e3`` None but for DOP853).
    dense : (m, n_all) array
        Rows making ``r4, r5, ...`` of the dense output (times ``h``).
    fac_min, fac_max : float
        Bounds of the step-size ratio.
    """

    def __init__(self, name, order, error_order, stages, c, a, b, e, e3, dense, fac_min,
                 fac_max):
        self.name, self.order, self.error_order, self.stages = name, order, error_order, stages
        self.c, self.a, self.b, self.e, self.e3, self.dense = c, a, b, e, e3, dense
        self.fac_min, self.fac_max = fac_min, fac_max
        # per stage: its node and its row of ``a`` (views made once, not per step)
        self.rows = [(float(c[i]), a[i, :i]) for i in range(len(c))]
        # the error estimate(s) as one matrix over the first ``stages + 1`` stages
        self.err = e[None, :] if e3 is None else np.vstack((e[:stages + 1], e3))

    @classmethod
    def build(cls, name, spec, order, error_order, stages, fac_min, fac_max):
        n_all = len(spec["c"])
        a = np.zeros((n_all, n_all))
        for i, row in spec["a"].items():
            for j, v in row.items():
                a[i, j] = v
        b = _rows([spec["b"]], stages)[0]
        e = _rows([spec["e"]], stages + 1)[0]
        e3 = None
        if "b3" in spec:                 # the 3rd-order estimate: b less b3
            e3 = np.zeros(stages + 1)
            e3[:stages] = b
            for j, v in spec["b3"].items():
                e3[j] -= v
        return cls(name, order, error_order, stages, np.array(spec["c"], float), a, b, e, e3,
                   _rows(spec["dense"], n_all), fac_min, fac_max)


#: the pairs by name; the step-ratio bounds are those of Hairer's codes
#: DOPRI5 (0.2, 10) and DOP853 (1/3, 6)
PAIRS = {
    "RK45": Pair.build("RK45", rk_tableaux.DP54, 5, 4, 6, 0.2, 10.0),
    "DOP853": Pair.build("DOP853", rk_tableaux.DOP853, 8, 7, 12, 1.0 / 3.0, 6.0),
}


class Events:
    """Event functions for :func:`solve`.

    Parameters
    ----------
    fun : callable ``fun(t, y) -> (m,) array``
        The event functions, one component each.
    direction : (m,) array
        ``+1``: only rising crossings (negative to non-negative) count;
        ``-1``: only falling ones (positive to non-positive); ``0``: both.
        A terminal component exactly zero at the start of the integration
        counts as on the side its direction leaves (negative for ``+1``,
        positive for ``-1``; scipy's ``solve_ivp`` finds such a crossing
        too): a switch that starts on its boundary and goes on is found at
        once.  A non-terminal one starting at zero (a maximum where the
        run starts) is no crossing.
    terminal : (m,) bool array
        Whether an event of that component ends the integration.
    """

    __slots__ = ("fun", "direction", "terminal")

    def __init__(self, fun, direction, terminal):
        self.fun = fun
        self.direction = np.asarray(direction, float)
        self.terminal = np.asarray(terminal, bool)


class Result:
    """What :func:`solve` found.

    Attributes
    ----------
    t, y : float, (n,) array
        Where it stopped: ``t1``, a terminal event or a failure.
    status : int
        0: reached ``t1``; 1: stopped on a terminal event; -1: failed.
    message : str
    t_events, y_events : list of lists
        Per event function, the located times and the states there (up to
        and including the terminal event).
    y_eval : (k, n) array
        The states at the first ``k`` requested output times, those before
        ``t``, read from the dense output.
    nfev : int
        Evaluations of ``f``.
    """

    __slots__ = ("t", "y", "status", "message", "t_events", "y_events", "y_eval", "nfev")


def rms(v: np.ndarray) -> float:
    return math.sqrt(float(np.dot(v, v)) / v.size) if v.size else 0.0


def locate_root(g, ta: float, ga: float, tb: float, gb: float, tol: float):
    """A root of the scalar ``g`` in ``[ta, tb]`` where ``ga`` and ``gb`` (its
    values at the ends) differ in sign or one is zero: the end of a bracket
    narrower than ``tol`` on ``gb``'s side (the side the crossing leads to).

    Illinois' modified regula falsi, with a bisection whenever the bracket
    fails to halve in three iterations, so at most ``3 log2(width / tol)``
    or so evaluations.
    """
    sa = 1.0 if ga > 0.0 else -1.0             # ga's side: g strictly of this sign
    width = tb - ta
    since_halved, side_last = 0, 0
    while tb - ta > tol:
        if since_halved >= 3:
            tm = 0.5 * (ta + tb)
        else:
            tm = tb - gb * (tb - ta) / (gb - ga) if gb != ga else 0.5 * (ta + tb)
            if not ta < tm < tb:
                tm = 0.5 * (ta + tb)
        gm = g(tm)
        if gm * sa <= 0.0:                 # left ga's side (zero counts as left)
            tb, gb = tm, gm
            if side_last == -1:
                ga *= 0.5                 # Illinois: halve the stale end's weight
            side_last = -1
        else:
            ta, ga = tm, gm
            if side_last == 1:
                gb *= 0.5
            side_last = 1
        since_halved += 1
        if tb - ta <= 0.5 * width:
            since_halved, width = 0, tb - ta
    return tb


def _stages(pair: Pair, f, t, y, h, K):
    """Stages ``1 .. stages - 1`` of the step ``h`` from ``(t, y)`` into ``K``
    (``K[0] = f(t, y)`` given); the solution at ``t + h``."""
    rows = pair.rows
    for i in range(1, pair.stages):
        ci, ai = rows[i]
        K[i] = f(t + ci * h, y + h * (ai @ K[:i]))
    return y + h * (pair.b @ K[:pair.stages])


def single_step(pair: Pair | str, f, t: float, y, h: float):
    """One step of length ``h`` from ``(t, y)``, without error control (for
    tests of the orders): the solution at ``t + h`` and its dense output,
    a function of the fraction ``s`` of the step."""
    pair = PAIRS[pair] if isinstance(pair, str) else pair
    y = np.array(y, dtype=float)
    K = np.empty((len(pair.c), y.size))
    R = np.empty((4 + len(pair.dense), y.size))
    K[0] = f(t, y)
    y_new = _stages(pair, f, t, y, h, K)
    K[pair.stages] = f(t + h, y_new)
    _dense_coefficients(pair, f, t, y, y_new, h, K, R)
    return y_new, lambda s: _dense_eval(R, s)


def _dense_coefficients(pair: Pair, f, t, y, y_new, h, K, R):
    """Fill ``R`` with the dense output's nested coefficients of the step
    ``(t, y) -> (t + h, y_new)`` (``K`` holds its stages and the slope at
    its end); DOP853 evaluates its three extra stages here."""
    s = pair.stages
    for i in range(s + 1, len(pair.c)):
        ci, ai = pair.rows[i]
        K[i] = f(t + ci * h, y + h * (ai @ K[:i]))
    R[0] = y
    np.subtract(y_new, y, out=R[1])
    np.subtract(h * K[0], R[1], out=R[2])
    R[3] = R[1] - h * K[s] - R[2]
    np.dot(pair.dense, K, out=R[4:])
    R[4:] *= h


def _dense_eval(R, s):
    """The dense output with coefficients ``R`` at fractions ``s`` (scalar
    or ``(k, 1)``)."""
    s1 = 1.0 - s
    v = R[-1]
    for k in range(len(R) - 1, 0, -1):
        v = R[k - 1] + (s if k % 2 else s1) * v
    return v


def _initial_step(f, t0, y0, f0, t1, rtol, atol, max_step, order):
    """The starting step of Hairer, Norsett & Wanner (sec. II.4)."""
    scale = atol + rtol * np.abs(y0)
    d0, d1 = rms(y0 / scale), rms(f0 / scale)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, max_step, t1 - t0)
    f1 = f(t0 + h0, y0 + h0 * f0)
    d2 = rms((f1 - f0) / scale) / h0
    big = max(d1, d2)
    h1 = max(1e-6, h0 * 1e-3) if big <= 1e-15 else (0.01 / big) ** (1.0 / order)
    return min(100.0 * h0, h1, max_step, t1 - t0)


def solve(pair: Pair | str, f, t0: float, y0, t1: float, *, rtol: float, atol: float,
          max_step: float = math.inf, events: Events | None = None,
          t_eval=None) -> Result:
    """Integrate ``y' = f(t, y)`` from ``t0`` to ``t1 > t0``.

    Parameters
    ----------
    pair : :class:`Pair` or ``"RK45"`` / ``"DOP853"``
    f : callable ``f(t, y) -> (n,) array``
        Called with a fresh array each time; at each accepted step's end it
        is evaluated last before the event functions, at the same array.
    rtol, atol : float
        Tolerances of the error control.
    max_step : float
        Largest step.
    events : :class:`Events` or None
    t_eval : increasing array or None
        Output times; those before where the integration stops are read from
        the dense output into ``Result.y_eval``.

    Returns
    -------
    :class:`Result`
    """
    if isinstance(pair, str):
        pair = PAIRS[pair]
    t = float(t0)
    t1 = float(t1)
    y = np.array(y0, dtype=float)
    n, s = y.size, pair.stages
    c, e, e3 = pair.c, pair.e, pair.e3
    K = np.empty((len(c), n))
    R = np.empty((4 + len(pair.dense), n))
    K[0] = f(t, y)
    nfev = 1
    res = Result()
    g = None
    if events is not None:
        g = np.array(events.fun(t, y), float)
        m = g.size
        # a terminal component exactly zero at the start lies on the side
        # its direction leaves: a run started where a contact touches sees
        # it close if it goes on
        on = (g == 0.0) & (events.direction != 0.0) & events.terminal
        g[on] = -events.direction[on] * _TINY
        rising = events.direction >= 0
        falling = events.direction <= 0
        res.t_events, res.y_events = [[] for _ in range(m)], [[] for _ in range(m)]
    else:
        res.t_events, res.y_events = [], []
    t_eval = np.empty(0) if t_eval is None else np.asarray(t_eval, float)
    n_eval, outs = 0, []
    if not t < t1:                                    # nothing to integrate
        res.t, res.y, res.status, res.message, res.nfev = t, y, 0, "reached the end", nfev
        res.y_eval = np.empty((0, n))
        return res
    abs_y = np.abs(y)
    h_abs = _initial_step(f, t, y, K[0], t1, rtol, atol, max_step, pair.order)
    nfev += 1
    expo = -1.0 / (pair.error_order + 1)
    status, message, rejected = 0, "reached the end", False
    while t < t1:
        min_step = 10.0 * (math.nextafter(t, math.inf) - t)
        h_abs = min(h_abs, max_step)
        while True:                                   # until a step is accepted
            if not h_abs >= min_step:                 # NaN too: a non-finite f
                status = -1
                message = (f"the step size {h_abs:.3g} s fell below the spacing of "
                           f"numbers at t = {t:.17g} s (or f is not finite there)")
                break
            t_new = t + h_abs
            if t_new >= t1 or t1 - t_new < min_step:
                t_new = t1
            h = h_abs = t_new - t
            y_new = _stages(pair, f, t, y, h, K)
            nfev += s - 1
            scale = np.abs(y_new)
            np.maximum(scale, abs_y, out=scale)
            scale *= rtol
            scale += atol
            if e3 is None:                            # the slope at the end enters
                K[s] = f(t_new, y_new)
                nfev += 1
                err = abs(h) * rms((e @ K[:s + 1]) / scale)
            else:
                ev = pair.err[:, :s] @ K[:s]          # the 5th- and 3rd-order estimates
                ev /= scale
                q5, q3 = np.einsum("ij,ij->i", ev, ev).tolist()
                den = q5 + 0.01 * q3
                err = abs(h) * q5 / math.sqrt(n * den) if q5 != 0.0 else 0.0  # NaN stays
            if err < 1.0:
                fac = pair.fac_max if err == 0.0 else min(pair.fac_max, SAFETY * err ** expo)
                if rejected:
                    fac = min(1.0, fac)
                h_next = h_abs * fac
                rejected = False
                break
            h_abs *= max(pair.fac_min, SAFETY * err ** expo)
            rejected = True
        if status == -1:
            break
        if e3 is not None:
            K[s] = f(t_new, y_new)
            nfev += 1
        t_stop, y_stop = t_new, y_new
        dense = False
        if g is not None:
            g_new = np.array(events.fun(t_new, y_new), float)
            up = rising & (g < 0.0) & (g_new >= 0.0)
            down = falling & (g > 0.0) & (g_new <= 0.0)
            active = np.flatnonzero(up | down)
            if active.size:
                _dense_coefficients(pair, f, t, y, y_new, h, K, R)
                nfev += len(c) - s - 1
                dense = True
                tol = 4.0 * _EPS * max(abs(t), abs(t_new)) + _EPS * h
                found = []
                for j in active:
                    def gj(tt, j=j):
                        return float(events.fun(tt, _dense_eval(R, (tt - t) / h))[j])
                    found.append((locate_root(gj, t, float(g[j]), t_new, float(g_new[j]), tol),
                                  int(j)))
                found.sort()
                for tr, j in found:
                    ye = y_new if tr == t_new else _dense_eval(R, (tr - t) / h)
                    res.t_events[j].append(tr)
                    res.y_events[j].append(ye)
                    if events.terminal[j]:
                        t_stop, y_stop = tr, ye
                        status, message = 1, "a terminal event occurred"
                        break
            g = g_new
        if n_eval < t_eval.size and t_eval[n_eval] < t_stop:
            k = n_eval + int(np.searchsorted(t_eval[n_eval:], t_stop, side="left"))
            if not dense:
                _dense_coefficients(pair, f, t, y, y_new, h, K, R)
                nfev += len(c) - s - 1
            if k == n_eval + 1:                      # one output: scalar arithmetic
                outs.append(_dense_eval(R, (float(t_eval[n_eval]) - t) / h)[None, :])
            else:
                outs.append(_dense_eval(R, ((t_eval[n_eval:k] - t) / h)[:, None]))
            n_eval = k
        t, y = t_stop, y_stop
        if status == 1:
            break
        abs_y = np.abs(y)
        K[0] = K[s]
        h_abs = h_next
    res.t, res.y, res.status, res.message, res.nfev = t, y, status, message, nfev
    res.y_eval = np.concatenate(outs) if outs else np.empty((0, n))
    return res
