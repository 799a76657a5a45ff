"""Scene files: TOML to validated objects.

A scene declares its subsystems, contacts, effects, coupling scheme, end
time and outputs; nothing undeclared is simulated.  Every value is checked
when the file is read, and a :class:`SceneError` names the file, the key path
and what was expected.  Variants (``[variants.NAME]``) are tables of
overrides merged into the scene; ``--set key.path=value`` applies after them.
"""
from __future__ import annotations

import copy
import logging
import math
import re
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from cosim.io import tomlread
from cosim.core.guard import (DEFAULT_CHATTER_SWITCHES, DEFAULT_CHATTER_WINDOW, DEFAULT_COUPLING_WARNING,
                    DEFAULT_ENERGY_FLOOR, DEFAULT_ENERGY_GROWTH, DEFAULT_ENERGY_WARNING,
                    GuardOptions)
from cosim.io.rundir import name_problem


__all__ = ["SceneError", "Scene", "load_scene", "parse_override", "read_toml_file",
           "SUBSYSTEM_TYPES"]

log = logging.getLogger(__name__)

STRUCTURE_TYPES = ("chain", "beam", "cable", "string", "rod")
SUBSYSTEM_TYPES = ("multibody", "rigid", "fmu") + STRUCTURE_TYPES
_MISSING = object()
#: most elements (or masses) a structure may have: a mesh beyond it is refused
#: when the scene is read, before anything is assembled
MAX_ELEMENTS = 20_000
#: most steps a run may ask for (end time over a macro or integrator step)
MAX_STEPS = 10**9
#: most memory the structures of a scene may need, as estimated before they
#: are built (:func:`structure_memory`) [bytes]
MAX_MEMORY = 4 * 2**30
#: rule name -> (text, check)
_RULES = {">0": ("> 0", lambda v: v > 0), ">=0": (">= 0", lambda v: v >= 0)}


class SceneError(ValueError):
    """A scene file that cannot be used, with the file and key path."""

    def __init__(self, file, key: str, message: str):
        self.file, self.key = str(file), key
        where = f"`{key}` " if key else ""
        super().__init__(f"{self.file}: {where}{message}")


def _check_name(file, key: str, name, what: str) -> None:
    """Refuse a name that becomes a path or a key (a run folder, an export
    file, a sweep point's folder, a ``series.npz`` member) unless it is a
    plain word (:data:`cosim.io.rundir.NAME_RULE`)."""
    problem = name_problem(name)
    if problem is not None:
        raise SceneError(file, key, " ".join(filter(None, (what, problem))))


def _type_name(v) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "an array", dict: "a table"}.get(type(v), type(v).__name__)


class _Table:
    """A table of the scene being read: typed getters that record what was
    used, so that :meth:`finish` can reject unknown keys."""

    def __init__(self, data, path: tuple, file):
        self.data, self.path, self.file = data, path, file
        self.used: set[str] = set()

    def key(self, k: str = "") -> str:
        return ".".join(self.path + ((k,) if k else ()))

    def error(self, k: str, message: str):
        raise SceneError(self.file, self.key(k), message)

    def has(self, k: str) -> bool:
        return k in self.data

    def raw(self, k: str, default=_MISSING):
        self.used.add(k)
        if k not in self.data:
            if default is _MISSING:
                self.error(k, "is required but missing")
            return default
        return self.data[k]

    def number(self, k, default=_MISSING, *, rule: str | None = None, unit: str = ""):
        v = self.raw(k, default)
        if v is default and default is not _MISSING:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.error(k, f"must be a number{' [' + unit + ']' if unit else ''}, "
                          f"got {_type_name(v)} {v!r}")
        try:
            v = float(v)
        except OverflowError:
            v = math.inf
        if not math.isfinite(v):
            self.error(k, f"must be finite, got {v!r}")
        if rule is not None and not _RULES[rule][1](v):
            self.error(k, f"must be {_RULES[rule][0]}{' ' + unit if unit else ''}, got {v!r}")
        return v

    def integer(self, k, default=_MISSING, *, low: int | None = None,
                high: int | None = None):
        v = self.raw(k, default)
        if v is default and default is not _MISSING:
            return v
        if isinstance(v, bool) or not isinstance(v, int):
            self.error(k, f"must be an integer, got {_type_name(v)} {v!r}")
        if low is not None and v < low:
            self.error(k, f"must be >= {low}, got {v!r}")
        if high is not None and v > high:
            self.error(k, f"must be <= {high}, got {v!r}")
        return v

    def string(self, k, default=_MISSING, *, choices=None):
        v = self.raw(k, default)
        if v is default and default is not _MISSING:
            return v
        if not isinstance(v, str):
            self.error(k, f"must be a string, got {_type_name(v)} {v!r}")
        if choices is not None and v not in choices:
            self.error(k, f"must be one of {sorted(choices)}, got {v!r}")
        return v

    def boolean(self, k, default=_MISSING):
        v = self.raw(k, default)
        if not isinstance(v, bool):
            self.error(k, f"must be true or false, got {_type_name(v)} {v!r}")
        return v

    def vec2(self, k, default=_MISSING, *, unit="m", nonzero=False):
        v = self.raw(k, default)
        if v is default and default is not _MISSING:
            return v
        if (not isinstance(v, list) or len(v) != 2
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            self.error(k, f"must be an array of two numbers [{unit}], got {v!r}")
        try:
            v = [float(x) for x in v]
        except OverflowError:
            v = [math.inf]
        if not all(math.isfinite(x) for x in v):
            self.error(k, f"must be finite, got {self.data[k]!r}")
        if nonzero and v[0] == 0 and v[1] == 0:
            self.error(k, f"must be a non-zero vector, got {v!r}")
        return (float(v[0]), float(v[1]))

    def table(self, k, default=_MISSING) -> "_Table":
        v = self.raw(k, {} if default is not _MISSING else _MISSING)
        if not isinstance(v, dict):
            self.error(k, f"must be a table, got {_type_name(v)} {v!r}")
        return _Table(v, self.path + (k,), self.file)

    def tables(self, k, default=_MISSING) -> list[tuple[str, "_Table"]]:
        t = self.table(k, default)
        out = []
        for name in t.data:
            out.append((name, t.table(name)))
        return out

    def finish(self) -> None:
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            where = self.key() or "the top level"
            raise SceneError(self.file, self.key(unknown[0]),
                             f"is not a known key of {where}; known keys are "
                             f"{sorted(self.used)}")


# ---------------------------------------------------------------- overrides
def _merge(base: dict, over: dict) -> dict:
    """Merge ``over`` into ``base`` key by key.  A table that names another
    ``type`` than the one it overrides (a law, a drive) replaces it whole."""
    for k, v in over.items():
        old = base.get(k)
        if (isinstance(v, dict) and isinstance(old, dict)
                and not ("type" in v and v["type"] != old.get("type"))):
            _merge(old, v)
        else:
            base[k] = copy.deepcopy(v)
    return base


def parse_override(text: str, file="--set") -> tuple[list[str], object]:
    """Parse ``a.b.c=value``; the value is read as a TOML value, else a string."""
    if "=" not in text:
        raise SceneError(file, "", f"override {text!r} must read key.path=value")
    key, value = text.split("=", 1)
    if key.count(".") >= tomlread.MAX_DEPTH:
        raise SceneError(file, "", f"a --set key must have at most {tomlread.MAX_DEPTH} "
                                   f"parts (`cosim.io.tomlread.MAX_DEPTH`), got "
                                   f"{key.count('.') + 1}")
    path = [p.strip() for p in key.strip().split(".")]
    if not all(path):
        raise SceneError(file, key, f"override {text!r} has an empty key")
    try:
        parsed = tomlread.loads(f"v = {value.strip()}")["v"]
    except tomlread.TomlLimitError as exc:
        raise SceneError(file, key.strip(), f"given with --set {exc}") from None
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return path, parsed


def _apply_override(data: dict, path: list[str], value, file) -> None:
    if path[0] in ("variants", "default_variant"):
        raise SceneError(file, ".".join(path), "is chosen with --variant, not with --set")
    node = data
    for i, k in enumerate(path[:-1]):
        nxt = node.setdefault(k, {})
        if not isinstance(nxt, dict):
            raise SceneError(file, ".".join(path[:i + 1]),
                             f"is {_type_name(nxt)}, so --set cannot reach "
                             f"`{'.'.join(path)}` inside it")
        node = nxt
    node[path[-1]] = value


# ------------------------------------------------------------------- specs
@dataclass(frozen=True)
class Scene:
    """A validated scene, ready to :meth:`build`.

    Attributes
    ----------
    name, path, variant : str
    t_end : float
        End time [s].
    scheme : str
        Default coupling scheme's name.
    scheme_options : dict
        Options of that scheme, validated.
    scheme_tables : dict
        Scheme name -> options that apply only when that scheme runs
        (``[scheme.NAME]`` tables, e.g. the monolithic reference's tolerances
        in a scene whose default is a co-simulation), validated.
    data : dict
        The merged scene table (after variant and overrides).
    guard : GuardOptions
        The run guard's settings (``[guard]``: ``energy_growth``,
        ``energy_check``, ``energy_floor``, ``chatter_switches``,
        ``chatter_window``), see :mod:`cosim.core.guard`.
    """

    name: str
    path: str
    variant: str | None
    t_end: float
    scheme: str
    scheme_options: dict
    output_every: int
    subsystems: tuple
    contacts: tuple
    gravity: tuple | None
    data: dict = field(repr=False)
    export: tuple = ()
    export_every: int = 1
    scheme_tables: dict = field(default_factory=dict)
    guard: GuardOptions = GuardOptions()

    def build(self, scheme: str | None = None):
        """Make the coupled system and the scheme (optionally another one)."""
        from cosim.scene.build import build_system
        return build_system(self, scheme)


def load_scene(path, variant: str | None = None, overrides=(), scheme: str | None = None
               ) -> Scene:
    """Read, merge and validate a scene file.

    Parameters
    ----------
    path : path-like
    variant : str, optional
        Name of a ``[variants.NAME]`` table; the scene's ``default_variant``
        when omitted.
    overrides : iterable of str or (path list, value)
        ``key.path=value`` overrides, applied after the variant.
    scheme : str, optional
        Replace the scene's coupling scheme; options the new scheme does not
        take are dropped with one warning naming them.

    Raises
    ------
    SceneError
    """
    file = Path(path)
    data = read_toml_file(file)
    variants = data.pop("variants", {})
    if not isinstance(variants, dict) or not all(isinstance(v, dict) for v in variants.values()):
        raise SceneError(file, "variants", "must be a table of tables")
    for vname in variants:
        _check_name(file, "variants", vname, "names a variant that")
    default_variant = data.pop("default_variant", None)
    if default_variant is not None and not isinstance(default_variant, str):
        raise SceneError(file, "default_variant",
                         f"must be a string, got {_type_name(default_variant)} "
                         f"{default_variant!r}")
    chosen = variant if variant is not None else default_variant
    if chosen is not None:
        if chosen not in variants:
            key = "default_variant" if variant is None else "variants"
            raise SceneError(file, key,
                             f"names no variant {chosen!r}; variants are {sorted(variants)}")
        _merge(data, variants[chosen])
    for ov in overrides:
        p, v = parse_override(ov, file) if isinstance(ov, str) else ov
        _apply_override(data, list(p), v, file)
    if scheme is not None:
        sch = data.setdefault("scheme", {})
        if not isinstance(sch, dict):
            raise SceneError(file, "scheme", f"must be a table, got {_type_name(sch)} {sch!r}")
        sch["name"] = scheme
    try:
        tomlread.check_depth(data)          # an override may reach deeper than the file
    except tomlread.TomlLimitError as exc:
        raise SceneError(file, exc.key, str(exc)) from None
    return _validate(data, file, chosen)


def read_toml_file(file) -> dict:
    """Read a scene or a study file within the limits of :mod:`cosim.io.tomlread`
    (a regular file of at most 64 MiB, UTF-8, nested at most 32 levels, at
    most 10 000 keys).

    Raises
    ------
    SceneError
        Naming the file, if it cannot be read, passes a limit, or is not TOML.
    """
    try:
        return tomlread.read_toml(file)
    except OSError as exc:
        raise SceneError(file, "", f"cannot be read: {exc.strerror or exc}") from None
    except tomlread.TomlLimitError as exc:
        raise SceneError(file, exc.key, str(exc)) from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(file, "", f"is not valid TOML: {exc}") from None


def _validate(data: dict, file, variant) -> Scene:
    from cosim.core.schemes import COUPLING_SCHEMES

    top = _Table(data, (), file)
    name = top.string("name", file.stem)
    _check_name(file, "name", name, "(a run folder's default name; the file's name when the "
                                    "scene gives none)" if "name" not in data else "")
    top.string("description", "")
    t_end = top.number("t_end", rule=">0", unit="s")

    sch = top.table("scheme")
    scheme_name = sch.string("name", choices=COUPLING_SCHEMES)
    cls = COUPLING_SCHEMES[scheme_name]
    opts, ignored, tables = {}, [], {}
    for k in list(sch.data):
        if k == "name":
            continue
        if k in COUPLING_SCHEMES and isinstance(sch.data[k], dict):
            sub = sch.table(k)
            other = COUPLING_SCHEMES[k]
            for ko in list(sub.data):
                if ko not in other.options:
                    sub.error(ko, f"is not an option of scheme `{k}`; its options are "
                                  f"{sorted(other.options)}")
            tables[k] = {ko: _scheme_option(sub, ko, other.options[ko]) for ko in sub.data}
            sub.finish()
            continue
        sch.used.add(k)
        if k not in cls.options and not any(k in c.options for c in COUPLING_SCHEMES.values()):
            sch.error(k, f"is not an option of any scheme; options of `{scheme_name}` are "
                         f"{sorted(cls.options)}")
        if k not in cls.options:
            other = next(c for c in COUPLING_SCHEMES.values() if k in c.options)
            _scheme_option(sch, k, other.options[k])      # still a valid value
            ignored.append(k)
            continue
        opts[k] = _scheme_option(sch, k, cls.options[k])
    if ignored:
        warnings.warn(f"{file}: scheme `{scheme_name}` ignores the options {sorted(ignored)}",
                      stacklevel=3)
    opts.update(tables.get(scheme_name, {}))
    if "macro_step" in cls.options and "macro_step" not in opts:
        sch.error("macro_step", f"is required by scheme `{scheme_name}` [s]")

    H = opts.get("macro_step")
    if H is not None and t_end / H > MAX_STEPS:
        sch.error("macro_step", f"is {H!r} s: {t_end!r} s would take {t_end / H:.3g} macro "
                                f"steps, more than {MAX_STEPS:.0e}")

    out = top.table("output", {})
    every = out.integer("every", 1, low=1)
    export = out.raw("export", [])
    if not isinstance(export, list) or not all(isinstance(x, str) for x in export):
        out.error("export", f"must be a list of structure names, got {export!r}")
    export_every = out.integer("export_every", 1, low=1)
    out.finish()

    eff = top.table("effects", {})
    gravity = None
    if eff.has("gravity"):
        g = eff.raw("gravity")
        if isinstance(g, list):
            gravity = eff.vec2("gravity", unit="m/s^2")
        else:
            gravity = (0.0, -eff.number("gravity", rule=">0", unit="m/s^2"))
    eff.finish()

    gd = top.table("guard", {})
    guard = GuardOptions(energy_growth=gd.number("energy_growth", DEFAULT_ENERGY_GROWTH,
                                                 rule=">0"),
                         energy_check=gd.boolean("energy_check", True),
                         energy_floor=gd.number("energy_floor", DEFAULT_ENERGY_FLOOR,
                                                rule=">=0", unit="J"),
                         energy_warning=gd.number("energy_warning", DEFAULT_ENERGY_WARNING,
                                                  rule=">0"),
                         coupling_warning=gd.number("coupling_warning",
                                                    DEFAULT_COUPLING_WARNING, rule=">0"),
                         chatter_switches=gd.integer("chatter_switches",
                                                     DEFAULT_CHATTER_SWITCHES, low=2,
                                                     high=10 ** 9),
                         chatter_window=gd.number("chatter_window", DEFAULT_CHATTER_WINDOW,
                                                  rule=">=0", unit="s"))
    gd.finish()

    subs = []
    for sname, st in top.tables("subsystems"):
        _check_name(file, "subsystems", sname, "names a subsystem that")
        if "." in sname:
            raise SceneError(file, "subsystems", f"names a subsystem {sname!r}: a subsystem's "
                                                 f"name holds no `.`, which separates it from "
                                                 f"the point in SUBSYSTEM.POINT")
        subs.append(_subsystem_spec(sname, st))
        step = subs[-1].get("max_step")
        if step is not None and t_end / step > MAX_STEPS:
            raise SceneError(file, f"subsystems.{sname}.integrator.max_step",
                             f"is {step!r} s: {t_end!r} s would take {t_end / step:.3g} "
                             f"steps, more than {MAX_STEPS:.0e}")
    if not subs:
        top.error("subsystems", "must declare at least one subsystem")
    _check_memory(subs, file)
    structures = [s["name"] for s in subs if s["type"] in STRUCTURE_TYPES]
    for name in export:
        if name not in structures:
            raise SceneError(file, "output.export", f"names {name!r}, which is not a structure "
                                                    f"of this scene; structures are {structures}")
    contacts = []
    for cname, ct in top.tables("contacts", {}):
        _check_name(file, "contacts", cname, "names a contact that")
        contacts.append(_contact_spec(cname, ct, subs))
    _check_conditions(contacts, file)
    top.finish()
    return Scene(name=name, path=str(file), variant=variant, t_end=t_end, scheme=scheme_name,
                 scheme_options=opts, output_every=every, subsystems=tuple(subs),
                 contacts=tuple(contacts), gravity=gravity, data=data,
                 export=tuple(export), export_every=export_every, scheme_tables=tables,
                 guard=guard)


def _scheme_option(sch: _Table, k, opt):
    v = sch.raw(k)
    if opt.kind is float:
        v = sch.number(k)
    elif opt.kind is int:
        v = sch.integer(k)
    elif opt.kind is bool:
        v = sch.boolean(k)
    elif opt.kind is str:
        v = sch.string(k)
    elif opt.kind is list and not isinstance(v, list):
        sch.error(k, f"must be an array, got {v!r}")
    if not opt.check(v):
        sch.error(k, f"must be {opt.rule}, got {v!r}")
    return v


def structure_memory(kind: str, size: int, n_modes: int | None, cutoff_hz: float | None
                     ) -> tuple[int, int, str]:
    """Estimate the memory that building a structure takes, before it is built.

    Parameters
    ----------
    kind : str
        ``chain``, ``beam``, ``cable``, ``string`` or ``rod``.
    size : int
        Masses of a chain, elements of the others.
    n_modes, cutoff_hz
        The structure's ``modes`` table (``count`` and ``cutoff_hz``).

    Returns
    -------
    n_dof : int
        Its degrees of freedom before constraints (an upper bound).
    bytes : int
        About the peak memory of its assembly and modal analysis [bytes]: a
        dense eigenproblem (every mode kept, or a structure of at most
        ``fem.modal.DENSE_LIMIT`` DOFs) holds about ten ``n x n`` arrays of
        doubles (9.4 measured for a chain of 2000 masses), and so does a
        chain, whose matrices are dense; a sparse one, a few ``n``-vectors per
        Lanczos vector (a lower bound with a cutoff alone, whose number of
        modes is found while solving).
    why : str
        What dominates, for the message.
    """
    from fem.modal import DENSE_LIMIT

    n = {"chain": size, "beam": 2 * (size + 1), "cable": 2 * (size + 1)}.get(kind, size + 1)
    dense = (n <= DENSE_LIMIT or (n_modes is None and cutoff_hz is None)
             or (n_modes is not None and n_modes >= n - 3))
    if dense or kind == "chain":
        nbytes = 10 * 8 * n * n
        why = f"dense {n} x {n} matrices"
        if not dense:
            why += " (a chain's matrices are dense whatever modes it keeps)"
        else:
            why += (" (every mode is kept: give `modes.count` or `modes.cutoff_hz`)"
                    if kind != "chain" else "")
        return n, nbytes, why
    k = n_modes if n_modes is not None else 16
    nbytes = 8 * n * (3 * max(2 * k + 1, 20) + 60)
    return n, nbytes, f"{k} Lanczos vectors of {n} DOFs"


def _check_memory(subs: list[dict], file) -> None:
    """Refuse a scene whose structures would need more than :data:`MAX_MEMORY`."""
    found = []
    for spec in subs:
        if spec["type"] not in STRUCTURE_TYPES:
            continue
        model, modes = spec["model"], spec["modes"]
        size = (len(model.masses) if spec["type"] == "chain" else model.n_elements)
        n, nbytes, why = structure_memory(spec["type"], size, modes["n_modes"],
                                          modes["cutoff_hz"])
        key = spec["key"] + (".masses" if spec["type"] == "chain" else ".elements")
        found.append((nbytes, key, n, why))
    total = sum(f[0] for f in found)
    if total > MAX_MEMORY:
        nbytes, key, n, why = max(found)
        others = (f"; with the other structures, {_size_text(total)}"
                  if total > nbytes else "")
        raise SceneError(file, key, f"makes a structure of {n} DOFs whose model and modes "
                                    f"need about {_size_text(nbytes)} ({why}){others}, more "
                                    f"than the {_size_text(MAX_MEMORY)} a scene may use "
                                    f"(`cosim.scene.load.MAX_MEMORY`)")


def _size_text(nbytes: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if nbytes < 1024 or unit == "GiB":
            return f"{nbytes:.3g} {unit}"
        nbytes /= 1024


def _subsystem_spec(name: str, t: _Table) -> dict:
    kind = t.string("type", choices=SUBSYSTEM_TYPES)
    spec = {"name": name, "type": kind, "key": t.key()}
    if kind in STRUCTURE_TYPES:
        spec.update(_structure_spec(t, kind))
    elif kind == "fmu":              # a Functional Mock-up Unit: cosim.scene.fmu
        from cosim.scene.fmu import fmu_spec
        spec.update(fmu_spec(t))
    elif kind == "rigid":
        pts = t.table("points")
        spec["points"] = {p: pts.vec2(p) for p in list(pts.data)}
        if not spec["points"]:
            t.error("points", "must name at least one point")
    else:
        integ = t.table("integrator", {})
        from cosim.core.ode import INTEGRATORS
        spec["integrator"] = integ.string("method", "rk4", choices=INTEGRATORS)
        spec["max_step"] = integ.number("max_step", None, rule=">0", unit="s")
        opts = {k: integ.number(k, rule=">0") for k in ("rtol", "atol") if integ.has(k)}
        if opts and spec["integrator"] == "rk4":
            integ.error(sorted(opts)[0], "is not an option of the fixed-step `rk4` (it takes "
                                         "`max_step` and `free_step`); adaptive methods take "
                                         "`rtol` and `atol`")
        if integ.has("free_step"):
            if spec["integrator"] != "rk4":
                integ.error("free_step", "is an option of `rk4` only (adaptive methods choose "
                                         "their steps)")
            opts["free_step"] = integ.number("free_step", rule=">0", unit="s")
        spec["integrator_options"] = opts
        integ.finish()
        bodies, joints, ports = [], [], {}
        names = []
        for bname, bt in t.tables("bodies"):
            jt = bt.table("joint")
            jname = jt.string("name")
            _check_name(t.file, jt.key("name"), jname, "")
            if jname in [j["name"] for j in joints]:
                jt.error("name", f"repeats joint {jname!r}; joint names must be unique in "
                                 f"subsystem `{name}`")
            parent = jt.string("parent", "ground")
            if parent != "ground" and parent not in names:
                jt.error("parent", f"must be `ground` or a body declared before `{bname}`; "
                                   f"declared so far: {names}")
            joint = {
                "name": jname,
                "kind": jt.string("type", choices=("revolute", "prismatic")),
                "parent": -1 if parent == "ground" else names.index(parent),
                "offset": jt.vec2("offset", (0.0, 0.0)),
                "axis": jt.vec2("axis", (1.0, 0.0), nonzero=True),
                "angle": jt.number("angle", 0.0, unit="rad"),
                "q0": jt.number("q0", 0.0),
                "dq0": jt.number("dq0", 0.0),
            }
            joint["effects"] = _joint_effects(jt, len(names))
            jt.finish()
            pts = bt.table("points", {})
            points = {p: pts.vec2(p) for p in list(pts.data)}
            for p in points:
                if p in ports:
                    pts.error(p, f"names a point already declared on body `{ports[p][0]}`; "
                                 f"point names must be unique in subsystem `{name}`")
                ports[p] = (bname, len(names), points[p])
            bodies.append({"name": bname, "mass": bt.number("mass", rule=">=0", unit="kg"),
                           "inertia": bt.number("inertia", 0.0, rule=">=0", unit="kg m^2"),
                           "com": bt.vec2("com", (0.0, 0.0)), "points": points,
                           "key": bt.key()})
            joints.append(joint)
            names.append(bname)
            bt.finish()
        if not bodies:
            t.error("bodies", "must declare at least one body")
        spec.update(bodies=bodies, joints=joints,
                    ports={p: (i, pt) for p, (_, i, pt) in ports.items()})
    t.finish()
    return spec


def _model(t: _Table, cls, **kw):
    """Construct a model object, turning its ValueError into a SceneError at
    the key of the parameter it names (or the table's)."""
    try:
        return cls(**kw)
    except (TypeError, ValueError) as exc:
        raise _model_error(t, exc) from None


def _model_error(t: _Table, exc: Exception) -> SceneError:
    msg = str(exc)
    m = re.match(r"`(\w+)(\[\d+\])?` (.*)", msg, re.S)
    if m and m.group(1) in t.data:
        return SceneError(t.file, t.key(m.group(1)) + (m.group(2) or ""), m.group(3))
    return SceneError(t.file, t.key(), msg)


def _floats(t: _Table, k: str) -> tuple:
    v = t.raw(k)
    if not isinstance(v, list) or not v or any(
            isinstance(x, bool) or not isinstance(x, (int, float)) for x in v):
        t.error(k, f"must be a non-empty array of numbers, got {v!r}")
    return tuple(float(x) for x in v)


def _trajectory(t: _Table):
    from multibody import TRAJECTORIES, MinimumJerk, Sinusoid, Table
    kind = t.string("type", choices=TRAJECTORIES)
    if kind == "table":
        out = _model(t, Table, times=_floats(t, "times"), values=_floats(t, "values"))
    elif kind == "minimum_jerk":
        out = _model(t, MinimumJerk, start=t.number("start"), end=t.number("end"),
                     t_start=t.number("t_start", unit="s"), t_end=t.number("t_end", unit="s"))
    else:
        out = _model(t, Sinusoid, amplitude=t.number("amplitude"),
                     frequency=t.number("frequency", unit="Hz"), phase=t.number("phase", 0.0),
                     offset=t.number("offset", 0.0))
    t.finish()
    return out


def _joint_effects(jt: _Table, index: int) -> list:
    """Springs, dampers and drives declared on a joint (none unless declared)."""
    if not any(jt.has(k) for k in ("spring", "damper", "drive")):
        return []                    # multibody.effects loads for the joints that need it
    from multibody import (ConstantTorque, JointDamper, JointSpring, PDTracking, Table,
                           TorqueTable)
    out = []
    if jt.has("spring"):
        st = jt.table("spring")
        out.append(_model(st, JointSpring, joint=index,
                          stiffness=st.number("stiffness", rule=">=0"),
                          rest=st.number("rest", 0.0)))
        st.finish()
    if jt.has("damper"):
        dt = jt.table("damper")
        out.append(_model(dt, JointDamper, joint=index, damping=dt.number("damping", rule=">=0")))
        dt.finish()
    if jt.has("drive"):
        dr = jt.table("drive")
        kind = dr.string("type", choices=("constant", "table", "pd"))
        if kind == "constant":
            out.append(_model(dr, ConstantTorque, joint=index, torque=dr.number("torque")))
        elif kind == "table":
            table = _model(dr, Table, times=_floats(dr, "times"), values=_floats(dr, "torques"))
            out.append(TorqueTable(index, table))
        else:
            out.append(_model(dr, PDTracking, joint=index, kp=dr.number("kp", rule=">=0"),
                              kd=dr.number("kd", rule=">=0"),
                              reference=_trajectory(dr.table("reference")),
                              max_torque=dr.number("max_torque", math.inf, rule=">0")))
        dr.finish()
    return out


def _structure_spec(t: _Table, kind: str) -> dict:
    """Model, ports, modes and initial state of a structure (a chain, beam,
    cable, string or rod)."""
    import fem
    kw = {}
    if kind == "chain":
        kw["masses"] = _floats(t, "masses")
        if len(kw["masses"]) > MAX_ELEMENTS:
            t.error("masses", f"must hold at most {MAX_ELEMENTS} masses, got "
                              f"{len(kw['masses'])}")
        kw["stiffnesses"] = _floats(t, "stiffnesses")
        kw["ground_below"] = t.boolean("ground_below", True)
        kw["spacing"] = t.number("spacing", rule=">0", unit="m")
        kw["origin"] = t.vec2("origin", (0.0, 0.0))
        kw["direction"] = t.vec2("direction", (0.0, 1.0), nonzero=True)
        cls, size = fem.Chain, len(kw["masses"])
    else:
        kw["length"] = t.number("length", rule=">0", unit="m")
        kw["density"] = t.number("density", rule=">0", unit="kg/m^3")
        kw["n_elements"] = t.integer("elements", low=1, high=MAX_ELEMENTS)
        kw["origin"] = t.vec2("origin", (0.0, 0.0))
        kw["axis"] = t.vec2("axis", (1.0, 0.0), nonzero=True)
        if kind in ("beam", "cable"):
            kw["youngs_modulus"] = t.number("youngs_modulus", rule=">0", unit="Pa")
            sec = t.table("section")
            if sec.has("diameter"):
                a, i = fem.circular_section(sec.number("diameter", rule=">0", unit="m"))
            else:
                a, i = fem.rectangular_section(sec.number("width", rule=">0", unit="m"),
                                               sec.number("height", rule=">0", unit="m"))
            sec.finish()
            kw.update(area=a, second_moment=i)
            kw["left"] = t.string("left", choices=fem.BEAM_ENDS)
            kw["right"] = t.string("right", choices=fem.BEAM_ENDS)
            kw["tension"] = (t.number("tension", rule=">0", unit="N") if kind == "cable"
                             else t.number("tension", 0.0, rule=">=0", unit="N"))
            kw["direction"] = t.vec2("direction", (0.0, 1.0), nonzero=True)
            cls = fem.Beam
        elif kind == "string":
            kw["tension"] = t.number("tension", rule=">0", unit="N")
            kw["area"] = t.number("area", rule=">0", unit="m^2")
            kw["direction"] = t.vec2("direction", (0.0, 1.0), nonzero=True)
            cls = fem.String
        else:
            kw["youngs_modulus"] = t.number("youngs_modulus", rule=">0", unit="Pa")
            kw["area"] = t.number("area", rule=">0", unit="m^2")
            kw["left"] = t.string("left", "free", choices=fem.ROD_ENDS)
            kw["right"] = t.string("right", "free", choices=fem.ROD_ENDS)
            cls = fem.Rod
        size = kw["length"]
    if t.has("rayleigh"):
        r = _floats(t, "rayleigh")
        if len(r) != 2:
            t.error("rayleigh", f"must be [a0, a1] ([1/s], [s]), got {list(r)}")
        kw["rayleigh"] = r
    model = _model(t, cls, **kw)
    pts = t.table("points")
    ports = {}
    for p in list(pts.data):
        v = pts.number(p, unit="m" if kind != "chain" else "")
        if kind == "chain":
            if not (v == int(v) and 0 <= v < size):
                pts.error(p, f"must be a mass index 0..{size - 1}, got {v!r}")
        elif not 0.0 <= v <= size:
            pts.error(p, f"must be a material coordinate in [0, {size:g}] m, got {v!r}")
        ports[p] = v
    if not ports:
        t.error("points", "must name at least one point")
    md = t.table("modes", {})
    modes = {"n_modes": md.integer("count", None, low=1),
             "cutoff_hz": md.number("cutoff_hz", None, rule=">0", unit="Hz")}
    md.finish()
    integ = t.table("integrator", {})
    method = integ.string("method", "exact", choices=fem.STRUCTURAL_INTEGRATORS)
    contact_step = integ.number("contact_step", 1e-6, rule=">0", unit="s")
    options = {k: integ.number(k) for k in ("beta", "gamma", "alpha", "rho_inf")
               if integ.has(k)}
    integ.finish()
    v0 = t.number("initial_velocity", 0.0, unit="m/s")
    if v0 and kind in ("beam", "cable"):
        t.error("initial_velocity", "a uniform initial velocity is offered for chains, "
                                    "strings and rods, whose DOFs are all translations")
    static = t.boolean("static_equilibrium", False)
    loads = {}
    if t.has("static_loads"):
        lt = t.table("static_loads")
        if not static:
            t.error("static_loads", "are point loads of the static state; they need "
                                    "`static_equilibrium = true`")
        for p in list(lt.data):
            if p not in ports:
                lt.error(p, f"names no point of this structure; its points are {sorted(ports)}")
            loads[p] = lt.number(p, unit="N")
        lt.finish()
    return {"model": model, "ports": ports, "modes": modes, "contact_step": contact_step,
            "integrator": method, "integrator_options": options,
            "initial_velocity": v0, "static_equilibrium": static, "static_loads": loads}


def _contact_spec(name: str, t: _Table, subs: list[dict]) -> dict:
    from couplers import CONTACT_LAWS

    def port(k):
        ref = t.string(k)
        sname, _, pname = ref.partition(".")
        match = [s for s in subs if s["name"] == sname]
        if not match or not pname:
            t.error(k, f"must read SUBSYSTEM.POINT with a declared subsystem "
                       f"({[s['name'] for s in subs]}), got {ref!r}")
        s = match[0]
        pts = s["points"] if s["type"] == "rigid" else s["ports"]
        if pname not in pts:
            t.error(k, f"names no point of subsystem `{sname}`; its points are {sorted(pts)}")
        return sname, pname

    a, b = port("a"), port("b")
    if a[0] == b[0]:
        t.error("b", f"must be on another subsystem than `a`, got {a[0]!r} twice")
    law_t = t.table("law")
    law_name = law_t.string("type", choices=CONTACT_LAWS)
    law_cls = CONTACT_LAWS[law_name]
    import dataclasses
    params = {}
    for f in dataclasses.fields(law_cls):
        if f.name in law_t.data:
            params[f.name] = law_t.number(f.name)
        elif f.default is dataclasses.MISSING:
            law_t.error(f.name, f"is required by law `{law_name}`")
    law_t.finish()
    law = _model(law_t, law_cls, **params)
    kinds = {s["name"]: s["type"] for s in subs}
    rigid_side = kinds[a[0]] == "rigid" or kinds[b[0]] == "rigid"
    if kinds[a[0]] == "rigid" and kinds[b[0]] == "rigid":
        t.error("b", "a contact between two rigid subsystems has nothing to simulate")
    placement = t.string("placement", "embedded" if rigid_side else "coupler",
                         choices=("embedded", "coupler"))
    if law.rigid and (placement != "embedded" or not rigid_side):
        t.error("placement", "a `rigid` law is resolved inside its moving side's integrator: "
                             "it needs placement `embedded` and a rigid side")
    host = None
    if t.has("host"):
        host = t.string("host", choices=(a[0], b[0]))
        if placement != "embedded" or rigid_side:
            t.error("host", "names the side that integrates an `embedded` contact between two "
                            "moving sides; here there is nothing to choose")
    follow = t.boolean("follow", False)
    if follow and kinds[b[0]] not in ("beam", "cable", "string", "rod"):
        t.error("follow", f"moves side b's point along a line structure; `{b[0]}` is a "
                          f"{kinds[b[0]]}")
    connection = _connection_spec(t, law)
    if connection is not None and placement == "embedded" and (
            kinds[a[0]] in STRUCTURE_TYPES or kinds[b[0]] in STRUCTURE_TYPES):
        t.error("placement", "a grasp or friction against a rigid side is not evaluated inside "
                             "a structure; set placement `coupler`")
    if connection is not None and placement == "embedded" and not rigid_side:
        t.error("placement", "a grasp or friction between two moving sides is exchanged by the "
                             "scheme, not hosted by one side; set placement `coupler`")
    spec = {"name": name, "a": a, "b": b, "normal": t.vec2("normal", unit="1", nonzero=True),
            "follow": follow,
            "offset": t.number("offset", 0.0, unit="m"), "law": law, "placement": placement,
            "host": host, "key": t.key(), "connection": connection}
    t.finish()
    return spec


_TRIGGER_FORMS = ('"start", "touch", { time = T } or { after = "CONTACT.grasp" (or '
                  '".release"), delay = D }')
_RELEASE_FORMS = '{ time = T } or { after = "CONTACT.grasp" (or ".release"), delay = D }'


def _trigger(t: _Table, k: str, release: bool):
    """``close`` or ``release`` of a grasp (see :class:`couplers.Trigger`)."""
    from couplers import Trigger
    forms = _RELEASE_FORMS if release else _TRIGGER_FORMS
    v = t.raw(k, None)
    if v is None:
        return None
    if isinstance(v, str):
        if release or v not in ("start", "touch"):
            t.error(k, f"must be {forms}, got {v!r}")
        return Trigger(v)
    if not isinstance(v, dict):
        t.error(k, f"must be {forms}, got {_type_name(v)} {v!r}")
    tt = t.table(k)
    if tt.has("time") == tt.has("after"):
        tt.error("", f"must be {forms}: give one of `time` and `after`, got {v!r}")
    if tt.has("time"):
        trig = Trigger("time", time=tt.number("time", rule=">=0", unit="s"))
    else:
        event = tt.string("after")
        cname, _, what = event.rpartition(".")
        if not cname or what not in ("grasp", "release"):
            tt.error("after", f"must read CONTACT.grasp or CONTACT.release, got {event!r}")
        trig = Trigger("after", event=event, delay=tt.number("delay", 0.0, rule=">=0", unit="s"))
    tt.finish()
    return trig


def _connection_spec(t: _Table, law):
    """A contact's ``grasp`` and ``friction`` tables, or None when it has neither
    (a friction coefficient of 0 builds no friction)."""
    if not (t.has("grasp") or t.has("friction")):
        return None                  # couplers.connection loads for the contacts that need it
    from couplers import Connection, Friction, Grasp
    grasp = close = release = friction = None
    if t.has("grasp"):
        gt = t.table("grasp")
        if law.rigid:
            t.error("grasp", "needs a penalty law: a `rigid` law is an impulse, it cannot hold")
        params = {k: gt.number(k, rule=">0" if k == "stiffness" else ">=0", unit=unit)
                  for k, unit in (("stiffness", "N/m"), ("damping", "N s/m"),
                                  ("tangential_stiffness", "N/m"),
                                  ("tangential_damping", "N s/m"))}
        grasp = _model(gt, Grasp, **params)
        close = _trigger(gt, "close", release=False)
        if close is None:
            gt.error("close", f"is required: when the grasp closes, {_TRIGGER_FORMS}")
        release = _trigger(gt, "release", release=True)
        if (close.kind == "time" and release is not None and release.kind == "time"
                and release.time <= close.time):
            gt.error("release", f"time {release.time!r} s must come after the close time "
                                f"{close.time!r} s")
        gt.finish()
    if t.has("friction"):
        ft = t.table("friction")
        if law.rigid:
            t.error("friction", "does not apply to a `rigid` law, which has its own Coulomb "
                                "friction in impulse space (`law.friction`)")
        mu = ft.number("coefficient", rule=">=0", unit="1")
        if mu > 0:
            friction = _model(ft, Friction, coefficient=mu,
                              slip_velocity=ft.number("slip_velocity", rule=">0", unit="m/s"))
        else:
            ft.number("slip_velocity", None, rule=">0", unit="m/s")
        ft.finish()
    if grasp is None and friction is None:
        return None
    return Connection(grasp, friction, close, release)


def _check_conditions(contacts: list[dict], file) -> None:
    """Every ``after`` names an event of a contact that can have it."""
    grasps = {c["name"] for c in contacts
              if c["connection"] is not None and c["connection"].grasp is not None}
    for c in contacts:
        conn = c["connection"]
        if conn is None or conn.grasp is None:
            continue
        for which, trig in (("close", conn.close), ("release", conn.release)):
            if trig is None or trig.kind != "after":
                continue
            other = trig.event.rpartition(".")[0]
            key = f"{c['key']}.grasp.{which}.after"
            if other not in grasps:
                raise SceneError(file, key, f"names {trig.event!r}, but no contact named "
                                            f"`{other}` has a grasp; contacts with a grasp are "
                                            f"{sorted(grasps)}")
            if which == "close" and other == c["name"]:
                raise SceneError(file, key, f"cannot wait for an event of its own grasp, got "
                                            f"{trig.event!r}")
