"""Validation of a scene's ``[subsystems.NAME]`` tables into typed specs:
multibody sides (bodies, joints, their springs, dampers and drives), rigid
sides, structures (chain, beam, cable, string, rod, and those installed
packages declare: :mod:`cosim.scene.plugin_structure`) and FMUs.

The keys each table accepts, and their defaults, are those of
:mod:`cosim.scene.keys`; the model packages load only for the subsystems a
scene declares.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from cosim.scene.checks import MAX_ELEMENTS, Table, build_model, check_name, echo, floats
from cosim.scene.specs import (STRUCTURE_TYPES, SUBSYSTEM_TYPES, BodySpec, JointSpec,
                               MultibodySpec, RigidSpec, StructureSpec)

__all__ = ["subsystem_spec"]


def subsystem_spec(name: str, t: Table):
    """The spec of subsystem ``name`` from its table (section ``subsystem``)."""
    kind = t.data.get("type")
    if isinstance(kind, str) and kind not in SUBSYSTEM_TYPES:
        from cosim.core.plugins import provide
        from fem import STRUCTURE_MODELS
        provide(STRUCTURE_MODELS, "cosim.structures", kind)    # an installed package's
        plugins = tuple(n for n in STRUCTURE_MODELS if n not in SUBSYSTEM_TYPES)
        if kind not in plugins:
            t.error("type", f"must be one of {sorted(SUBSYSTEM_TYPES + plugins)}, got "
                            f"{echo(kind)}; nor does an installed package declare a "
                            f"structure of that name (entry point `cosim.structures`)")
        _readable(STRUCTURE_MODELS[kind])
        t.string("type")
    else:
        kind = t.string("type", choices=SUBSYSTEM_TYPES)
    t.use(kind if kind in SUBSYSTEM_TYPES else f"structure.{kind}")
    if kind in STRUCTURE_TYPES or kind not in SUBSYSTEM_TYPES:
        spec = _structure_spec(name, t, kind)
    elif kind == "fmu":                # a Functional Mock-up Unit: cosim.scene.fmu
        from cosim.scene.fmu import fmu_spec
        spec = fmu_spec(name, t)
    elif kind == "rigid":
        pts = t.table("points", section="rigid.points")
        points = {p: pts.vec2(p) for p in list(pts.data)}
        pts.finish()
        if not points:
            t.error("points", "must name at least one point")
        spec = RigidSpec(name=name, key=t.key(), points=points)
    else:
        spec = _multibody_spec(name, t)
    t.finish()
    return spec


def _readable(cls) -> None:
    """Refuse plug-in structure ``cls`` if its fields cannot be read from a
    scene (:func:`cosim.scene.plugin_structure.model_class_problem`),
    naming the plug-in, not a key of the scene."""
    from cosim.core.plugin_guard import origin_of
    from cosim.errors import PluginError
    from cosim.scene.plugin_structure import model_class_problem
    problem = model_class_problem(cls)
    if problem:
        who = origin_of(cls) or f"structure {cls.__module__}.{cls.__qualname__}"
        raise PluginError(f"the plug-in {who} is refused: {problem}")


def _multibody_spec(name: str, t: Table) -> MultibodySpec:
    from cosim.core.ode import INTEGRATORS
    from cosim.core.plugins import provide

    integ = t.table("integrator", section="multibody.integrator")
    provide(INTEGRATORS, "cosim.integrators", integ.data.get("method"))
    method = integ.string("method", choices=INTEGRATORS)
    max_step = integ.number("max_step", None, rule=">0", unit="s")
    opts = {k: integ.number(k, rule=">0") for k in ("rtol", "atol") if integ.has(k)}
    if "rtol" in opts:
        from cosim.core.schemes.base import MIN_SOLVER_RTOL, SOLVER_RTOL_RULE
        if not opts["rtol"] >= MIN_SOLVER_RTOL:
            integ.error("rtol", f"must be {SOLVER_RTOL_RULE}, got {opts['rtol']!r}")
    if opts and method == "rk4":
        integ.error(sorted(opts)[0], "is not an option of the fixed-step `rk4` (it takes "
                                     "`max_step` and `free_step`); adaptive methods take "
                                     "`rtol` and `atol`")
    if integ.has("free_step"):
        if method != "rk4":
            integ.error("free_step", "is an option of `rk4` only (adaptive methods choose "
                                     "their steps)")
        opts["free_step"] = integ.number("free_step", rule=">0", unit="s")
    integ.finish()
    bodies, joints, ports = [], [], {}
    names = []
    for bname, bt in t.tables("bodies", section="bodies", entries="body"):
        jt = bt.table("joint", section="joint")
        jname = jt.string("name")
        check_name(t.file, jt.key("name"), jname, "")
        if jname in [j.name for j in joints]:
            jt.error("name", f"repeats joint {echo(jname)}; joint names must be unique in "
                             f"subsystem `{name}`")
        parent = jt.string("parent")
        if parent != "ground" and parent not in names:
            jt.error("parent", f"must be `ground` or a body declared before `{bname}`; "
                               f"declared so far: {names}")
        joint = JointSpec(
            name=jname,
            kind=jt.string("type", choices=("revolute", "prismatic")),
            parent=-1 if parent == "ground" else names.index(parent),
            offset=jt.vec2("offset"),
            axis=jt.vec2("axis", nonzero=True),
            angle=jt.number("angle", unit="rad"),
            q0=jt.number("q0"),
            dq0=jt.number("dq0"),
            effects=tuple(_joint_effects(jt, len(names))))
        jt.finish()
        pts = bt.table("points", section="body.points")
        points = {p: pts.vec2(p) for p in list(pts.data)}
        pts.finish()
        for p in points:
            if p in ports:
                pts.error(p, f"names a point already declared on body `{ports[p][0]}`; "
                             f"point names must be unique in subsystem `{name}`")
            ports[p] = (bname, len(names), points[p])
        bodies.append(BodySpec(name=bname, mass=bt.number("mass", rule=">=0", unit="kg"),
                               inertia=bt.number("inertia", rule=">=0", unit="kg m^2"),
                               com=bt.vec2("com"), points=points, key=bt.key()))
        joints.append(joint)
        names.append(bname)
        bt.finish()
    if not bodies:
        t.error("bodies", "must declare at least one body")
    return MultibodySpec(name=name, key=t.key(), bodies=tuple(bodies), joints=tuple(joints),
                         ports={p: (i, pt) for p, (_, i, pt) in ports.items()},
                         integrator=method, max_step=max_step, integrator_options=opts)


def _structure_spec(name: str, t: Table, kind: str) -> StructureSpec:
    """Model, ports, modes and initial state of a structure (a chain, beam,
    cable, string or rod, or an installed package's)."""
    import fem
    from cosim.core.plugins import provide
    kw = {}
    plane = kind == "plane"
    if plane:                                # a body from a mesh: cosim.scene.plane
        from cosim.scene.plane import plane_model
        model, ports = plane_model(t, _rayleigh(t) if t.has("rayleigh") else None)
    elif kind not in STRUCTURE_TYPES:        # an installed package's (fem.StructureModel)
        model = _plugin_model(t, fem.STRUCTURE_MODELS[kind])
        size = model.length
    elif kind == "chain":
        kw["masses"] = floats(t, "masses")
        if len(kw["masses"]) > MAX_ELEMENTS:
            t.error("masses", f"must hold at most {MAX_ELEMENTS} masses, got "
                              f"{len(kw['masses'])}")
        kw["stiffnesses"] = floats(t, "stiffnesses")
        kw["ground_below"] = t.boolean("ground_below")
        kw["spacing"] = t.number("spacing", rule=">0", unit="m")
        kw["origin"] = t.vec2("origin")
        kw["direction"] = t.vec2("direction", nonzero=True)
        cls, size = fem.Chain, len(kw["masses"])
    else:
        kw["length"] = t.number("length", rule=">0", unit="m")
        kw["density"] = t.number("density", rule=">0", unit="kg/m^3")
        kw["n_elements"] = t.integer("elements", low=1, high=MAX_ELEMENTS)
        kw["origin"] = t.vec2("origin")
        kw["axis"] = t.vec2("axis", nonzero=True)
        if kind in ("beam", "cable"):
            kw["youngs_modulus"] = t.number("youngs_modulus", rule=">0", unit="Pa")
            sec = t.table("section", section="section")
            try:
                if sec.has("diameter"):
                    a, i = fem.circular_section(sec.number("diameter", rule=">0", unit="m"))
                else:
                    a, i = fem.rectangular_section(sec.number("width", rule=">0", unit="m"),
                                                   sec.number("height", rule=">0", unit="m"))
            except OverflowError:           # a power past the largest float
                a = i = math.inf
            sec.finish()
            if not (math.isfinite(a) and math.isfinite(i)):
                sizes = "`diameter` is" if sec.has("diameter") else "`width` and `height` are"
                sec.error("", f"must have a finite area and second moment: its {sizes} too "
                              "large (past the largest float)")
            kw.update(area=a, second_moment=i)
            kw["left"] = t.string("left", choices=fem.BEAM_ENDS)
            kw["right"] = t.string("right", choices=fem.BEAM_ENDS)
            kw["tension"] = (t.number("tension", rule=">0", unit="N") if kind == "cable"
                             else t.number("tension", 0.0, rule=">=0", unit="N"))
            kw["direction"] = t.vec2("direction", nonzero=True)
            cls = fem.Beam
        elif kind == "string":
            kw["tension"] = t.number("tension", rule=">0", unit="N")
            kw["area"] = t.number("area", rule=">0", unit="m^2")
            kw["direction"] = t.vec2("direction", nonzero=True)
            cls = fem.String
        else:
            kw["youngs_modulus"] = t.number("youngs_modulus", rule=">0", unit="Pa")
            kw["area"] = t.number("area", rule=">0", unit="m^2")
            kw["left"] = t.string("left", choices=fem.ROD_ENDS)
            kw["right"] = t.string("right", choices=fem.ROD_ENDS)
            cls = fem.Rod
        size = kw["length"]
    if kind in STRUCTURE_TYPES and not plane:
        if t.has("rayleigh"):
            kw["rayleigh"] = _rayleigh(t)
        model = build_model(t, cls, **kw)
    pts = t.table("points", section="structure.points") if not plane else None
    if not plane:
        ports = {}
    for p in list(pts.data) if not plane else ():
        v = pts.number(p, unit="m" if kind != "chain" else "")
        if kind == "chain":
            if not (v == int(v) and 0 <= v < size):
                pts.error(p, f"must be a mass index 0..{size - 1}, got {echo(v)}")
        elif not 0.0 <= v <= size:
            pts.error(p, f"must be a material coordinate in [0, {size:g}] m, got {echo(v)}")
        ports[p] = v
    if not plane:
        pts.finish()
    if not ports:
        t.error("points", "must name at least one point")
    md = t.table("modes", section="plane.modes" if plane else "modes")
    n_modes = md.integer("count", low=1)
    cutoff_hz = md.number("cutoff_hz", rule=">0", unit="Hz")
    correction = md.boolean("static_correction") if plane else False
    cache = md.string("cache") if plane else None
    if cache is not None:               # recorded where it was found, as a mesh is
        cache = md.data["cache"] = str(Path(t.file).resolve().parent / cache)
    md.finish()
    integ = t.table("integrator", section="structure.integrator")
    provide(fem.STRUCTURAL_INTEGRATORS, "cosim.integrators", integ.data.get("method"))
    method = integ.string("method", choices=fem.STRUCTURAL_INTEGRATORS)
    contact_step = integ.number("contact_step", rule=">0", unit="s")
    options = {k: integ.number(k) for k in ("beta", "gamma", "alpha", "rho_inf")
               if integ.has(k)}
    integ.finish()
    v0 = t.number("initial_velocity", unit="m/s") if not plane else t.vec2("initial_velocity",
                                                                           unit="m/s")
    if v0 and kind in ("beam", "cable"):
        t.error("initial_velocity", "a uniform initial velocity is offered for chains, "
                                    "strings and rods, whose DOFs are all translations")
    static = t.boolean("static_equilibrium")
    loads = {}
    if t.has("static_loads"):
        lt = t.table("static_loads", section="static_loads")
        if not static:
            t.error("static_loads", "are point loads of the static state; they need "
                                    "`static_equilibrium = true`")
        for p in list(lt.data):
            if p not in ports:
                lt.error(p, f"names no point of this structure; its points are {sorted(ports)}")
            loads[p] = lt.number(p, unit="N")
        lt.finish()
    return StructureSpec(name=name, key=t.key(), type=kind, model=model, ports=ports,
                         n_modes=n_modes, cutoff_hz=cutoff_hz, contact_step=contact_step,
                         integrator=method, integrator_options=options, initial_velocity=v0,
                         static_equilibrium=static, static_loads=loads,
                         static_correction=correction, modal_cache=cache)


def _rayleigh(t: Table) -> tuple:
    r = floats(t, "rayleigh")
    if len(r) != 2:
        t.error("rayleigh", f"must be [a0, a1] ([1/s], [s]), got {list(r)}")
    return r


def _read_model(t: Table, cls, rayleigh=None):
    """The model of plug-in structure ``cls`` from its scene table ``t``
    (whose section is the class's, :func:`cosim.scene.keys.structure_section`).

    ``rayleigh`` (read by the caller, as every structure's) goes to the
    model when given; a model without a ``rayleigh`` field refuses it at
    its key.
    """
    from cosim.scene.plugin_structure import field_reader, fields_of
    kw = {}
    for f, _ in fields_of(cls):
        if f.name == "rayleigh":
            continue
        meta = f.metadata
        if not t.has(f.name) and f.default is not dataclasses.MISSING:
            t.raw(f.name)                       # optional and not given: the class's default
            continue
        reader = field_reader(cls, f.name)
        unit = meta.get("unit", "")
        if reader == "number":
            kw[f.name] = t.number(f.name, rule=meta.get("rule"), unit=unit)
        elif reader == "integer":
            kw[f.name] = t.integer(f.name, low=meta.get("low"), high=meta.get("high"))
        elif reader == "boolean":
            kw[f.name] = t.boolean(f.name)
        elif reader == "string":
            kw[f.name] = t.string(f.name, choices=meta.get("choices"))
        elif reader == "vec2":
            kw[f.name] = t.vec2(f.name, unit=unit or "1", nonzero=bool(meta.get("nonzero")))
        else:
            kw[f.name] = floats(t, f.name)
    if rayleigh is not None:
        if "rayleigh" not in {f.name for f, _ in fields_of(cls)}:
            t.error("rayleigh", f"is not taken by the structure `{cls.name}`, whose model has "
                                f"no `rayleigh` field")
        kw["rayleigh"] = rayleigh
    return build_model(t, cls, **kw)


def _plugin_model(t: Table, cls):
    """The model of a plug-in structure, its length checked (the range of
    its points)."""
    model = _read_model(t, cls, _rayleigh(t) if t.has("rayleigh") else None)
    length = getattr(model, "length", None)
    if (isinstance(length, bool) or not isinstance(length, (int, float))
            or not (math.isfinite(length) and length > 0)):
        t.error("length", f"must be > 0 m, got {length!r}")
    return model


def _trajectory(t: Table):
    from multibody import TRAJECTORIES, MinimumJerk, Sinusoid, Table as Points
    kind = t.string("type", choices=TRAJECTORIES)
    t.use(f"reference.{kind}")
    if kind == "table":
        out = build_model(t, Points, times=floats(t, "times"), values=floats(t, "values"))
    elif kind == "minimum_jerk":
        out = build_model(t, MinimumJerk, start=t.number("start"), end=t.number("end"),
                          t_start=t.number("t_start", unit="s"),
                          t_end=t.number("t_end", unit="s"))
    else:
        out = build_model(t, Sinusoid, amplitude=t.number("amplitude"),
                          frequency=t.number("frequency", unit="Hz"), phase=t.number("phase"),
                          offset=t.number("offset"))
    t.finish()
    return out


def _joint_effects(jt: Table, index: int) -> list:
    """Springs, dampers and drives declared on a joint (none unless declared)."""
    if not any(jt.has(k) for k in ("spring", "damper", "drive")):
        return []                    # multibody.effects loads for the joints that need it
    from multibody import (ConstantTorque, JointDamper, JointSpring, PDTracking, Table as Points,
                           TorqueTable)
    out = []
    if jt.has("spring"):
        st = jt.table("spring", section="spring")
        out.append(build_model(st, JointSpring, joint=index,
                               stiffness=st.number("stiffness", rule=">=0"),
                               rest=st.number("rest")))
        st.finish()
    if jt.has("damper"):
        dt = jt.table("damper", section="damper")
        out.append(build_model(dt, JointDamper, joint=index,
                               damping=dt.number("damping", rule=">=0")))
        dt.finish()
    if jt.has("drive"):
        dr = jt.table("drive", section="drive.constant")
        kind = dr.string("type", choices=("constant", "table", "pd"))
        dr.use(f"drive.{kind}")
        if kind == "constant":
            out.append(build_model(dr, ConstantTorque, joint=index, torque=dr.number("torque")))
        elif kind == "table":
            table = build_model(dr, Points, times=floats(dr, "times"),
                                values=floats(dr, "torques"))
            out.append(TorqueTable(index, table))
        else:
            out.append(build_model(dr, PDTracking, joint=index, kp=dr.number("kp", rule=">=0"),
                                   kd=dr.number("kd", rule=">=0"),
                                   reference=_trajectory(dr.table("reference",
                                                                  section="reference.table")),
                                   max_torque=dr.number("max_torque", rule=">0")))
        dr.finish()
    return out
