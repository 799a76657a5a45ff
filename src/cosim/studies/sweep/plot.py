"""The figure of a sweep: a contact's count and its time in touch against the
swept parameter, each point marked by its impact regime.  matplotlib is
imported only when a figure is drawn.
"""
from __future__ import annotations

import re
from pathlib import Path

from cosim.io.rundir import atomic_write
from cosim.studies.sweep.grid import _text
from cosim.studies.sweep.table import _grid_keys

__all__ = ["plot_sweep"]


_NUMBER = re.compile(r"^(?P<prefix>.*?)(?P<value>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)$")


def _axis(rows: list[dict], x=None):
    """The plot's abscissa: a grid key's numbers (``x`` names the key), else the
    number that ends each variant's name under a shared prefix (``ms0.05`` ->
    0.05), else the points' places in grid order, labelled by name.  Returns
    the values, the axis label, the tick labels (None: a numeric axis) and
    the record key the abscissa comes from (None: the points' places)."""
    keys = _grid_keys(rows)
    if x is None:
        varying = [k for k in keys if len({_text(r[k]) for r in rows}) > 1]
        x = varying[0] if len(varying) == 1 else None
    elif not x.startswith("set."):
        x = f"set.{x}"
    if x is not None and all(isinstance(r.get(x), (int, float)) for r in rows):
        return [float(r[x]) for r in rows], x, None, x
    names = [r["variant"] or "" for r in rows]
    m = [_NUMBER.match(n) for n in names]
    if all(m) and len({g["prefix"] for g in m}) == 1 and len({r["variant"] for r in rows}) > 1:
        return [float(g["value"]) for g in m], f"variant {m[0]['prefix']}…", None, "variant"
    return list(range(len(rows))), "point", [r["point"] for r in rows], None


#: marker and colour of each regime in the plot
_REGIME_STYLE = {"backward": ("o", "tab:blue"), "backward+": ("s", "tab:green"),
                 "forward": ("^", "tab:red"), "none": ("x", "0.5"),
                 "open-ended": ("x", "0.5")}


def plot_sweep(rows: list[dict], path, *, contact: str | None = None, x: str | None = None,
               x_scale: float = 1.0, x_label: str | None = None, title: str | None = None
               ) -> Path:
    """Draw a sweep: the contact's count, and its time in touch and span (first
    touch to last release), against the swept parameter; each point marked by
    its impact regime when the table has one.  Needs matplotlib.

    Parameters
    ----------
    rows : list of dict
        Records of :func:`sweep` (or :func:`read_table`).
    path : path-like
        The image to write (its suffix picks the format), written whole by
        the checked writer (:func:`cosim.io.rundir.atomic_write`; its folder
        is made when missing, a link at ``path`` replaced, never followed).
    contact : str, optional
        The contact drawn; by default the first contact of the table (the
        axes' labels name it): name it where the scene has several.
    x : str, optional
        The grid key on the abscissa; by default the only grid key that
        varies, else the number ending the variants' names.
    x_scale : float
        Multiplies the abscissa (a stiffness over c_ref gives f).
    x_label, title : str, optional

    Raises
    ------
    ValueError
        If ``contact`` is given and the table holds other contacts only, or
        if no point finished (nothing to draw: no empty figure is written).
    """
    named = list(dict.fromkeys(k.split(".")[1] for r in rows for k in r
                               if k.startswith("contacts.") and k.endswith(".count")))
    if contact is None:
        contact = named[0] if named else "the contact"
    elif named and contact not in named:
        raise ValueError(f"`contact` must be one of the table's contacts "
                         f"({', '.join(named)}), got {contact!r}")
    if not any(r.get(f"contacts.{contact}.count") is not None for r in rows):
        raise ValueError(f"no point of the sweep finished ({len(rows)} in the table): "
                         f"nothing to draw")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs, label, ticks, x_key = _axis(rows, x)
    xs = [v * x_scale for v in xs] if ticks is None else xs
    ok = [i for i, r in enumerate(rows) if r.get(f"contacts.{contact}.count") is not None]
    ratio = [(rows[i].get("impact.rate_at_release"), rows[i].get("impact.rate_at_touch"))
             for i in ok]
    ratio = [a / b if isinstance(a, float) and isinstance(b, float) and b and a == a
             else None for a, b in ratio]
    has_ratio = any(v is not None for v in ratio)
    fig, axes = plt.subplots(3 if has_ratio else 2, 1, sharex=True,
                             figsize=(6.4, 7.6 if has_ratio else 5.6),
                             constrained_layout=True)
    ax1, ax2 = axes[0], axes[1]
    count = [rows[i][f"contacts.{contact}.count"] for i in ok]
    touch = [1e3 * rows[i][f"contacts.{contact}.in_touch_time"] for i in ok]
    span = []
    for i in ok:
        iv = rows[i][f"contacts.{contact}.intervals"]
        span.append(1e3 * (iv[-1][1] - iv[0][0]) if iv else 0.0)
    xo = [xs[i] for i in ok]
    # one line through the points that differ in the abscissa alone
    others = [k for k in ["variant", *_grid_keys(rows)] if k != x_key]
    lines: dict = {}
    for j, i in enumerate(ok):
        lines.setdefault(tuple(_text(rows[i].get(k)) for k in others) if x_key
                         else (), []).append(j)
    for n, js in enumerate(lines.values()):
        def pick(v):
            return [v[j] for j in js]
        ax1.plot(pick(xo), pick(count), color="0.6", lw=1, zorder=1)
        ax2.plot(pick(xo), pick(span), color="0.6", lw=1, ls="--",
                 label="first touch to last release" if n == 0 else None)
        ax2.plot(pick(xo), pick(touch), color="0.3", lw=1,
                 label="in touch (sum of intervals)" if n == 0 else None)
    regimes = [rows[i].get("impact.regime") for i in ok]
    seen = set()
    for xi, ci, ti, reg in zip(xo, count, touch, regimes):
        marker, colour = _REGIME_STYLE.get(reg, ("o", "k"))
        lab = reg if reg and reg not in seen else None
        seen.add(reg)
        ax1.scatter([xi], [ci], marker=marker, color=colour, s=45, zorder=2, label=lab)
        ax2.scatter([xi], [ti], marker=marker, color=colour, s=30, zorder=2)
    if has_ratio:
        ax3 = axes[2]
        for js in lines.values():
            js = [j for j in js if ratio[j] is not None]
            ax3.plot([xo[j] for j in js], [ratio[j] for j in js], color="0.6", lw=1, zorder=1)
        for xi, v, reg in zip(xo, ratio, regimes):
            if v is None:
                continue
            marker, colour = _REGIME_STYLE.get(reg, ("o", "k"))
            ax3.scatter([xi], [v], marker=marker, color=colour, s=30, zorder=2)
        ax3.axhline(0.0, color="k", lw=0.8)
        ax3.set_ylabel("striker's rate at 1st release\n/ its rate at touch", fontsize=8)
        ax3.text(0.99, 0.04, "< 0: turned back within the first contact",
                 transform=ax3.transAxes, ha="right", fontsize=7)
        ax3.grid(alpha=0.3)
    bottom = axes[-1]
    failed = [i for i, r in enumerate(rows) if r.get("status") != "finished"]
    for i in failed:
        ax1.axvline(xs[i], color="tab:red", lw=0.8, ls=":")
    if failed:
        ax1.text(0.01, 0.97, f"{len(failed)} point(s) did not finish (dotted)",
                 transform=ax1.transAxes, va="top", fontsize=8, color="tab:red")
    ax1.set_ylabel(f"contacts of {contact}")
    ax2.set_ylabel(f"time of {contact} [ms]")
    bottom.set_xlabel(x_label or label)
    if any(r is not None for r in regimes):
        ax1.legend(title="impact regime", fontsize=8, title_fontsize=8)
    ax2.legend(fontsize=8)
    if ticks is not None:
        bottom.set_xticks(xs, ticks, rotation=30, ha="right", fontsize=7)
    elif min(xs) > 0 and max(xs) / min(xs) >= 20:
        bottom.set_xscale("log")
    ax1.grid(alpha=0.3)
    ax2.grid(alpha=0.3)
    if title:
        ax1.set_title(title, fontsize=10)
    path = Path(path)
    fmt = path.suffix[1:].lower() or "png"
    try:
        # written whole through the checked writer: a link planted at
        # ``path`` is replaced, never followed
        return atomic_write(path, lambda fh: fig.savefig(fh, format=fmt, dpi=110), "wb")
    finally:
        plt.close(fig)
