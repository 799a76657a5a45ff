"""Validation of a scene's ``[contacts.NAME]`` tables into typed specs: the
two ports, the law, where the contact lives, and its grasp and friction.

The keys each table accepts, and their defaults, are those of
:mod:`cosim.scene.keys` (a law's are the fields of its dataclass).
"""
from __future__ import annotations

import dataclasses

from cosim.scene.checks import SceneError, Table, build_model, echo, type_name
from cosim.scene.specs import ContactSpec, StructureSpec

__all__ = ["contact_spec", "check_conditions"]

_TRIGGER_FORMS = ('"start", "touch", { time = T } or { after = "CONTACT.grasp" (or '
                  '".release"), delay = D }')
_RELEASE_FORMS = '{ time = T } or { after = "CONTACT.grasp" (or ".release"), delay = D }'


def contact_spec(name: str, t: Table, subs: list) -> ContactSpec:
    """The spec of contact ``name`` from its table (section ``contact``),
    between points of the subsystems ``subs`` (their specs)."""
    from cosim.core.plugins import provide
    from couplers import CONTACT_LAWS

    def port(k):
        ref = t.string(k)
        sname, _, pname = ref.partition(".")
        match = [s for s in subs if s.name == sname]
        if not match or not pname:
            t.error(k, f"must read SUBSYSTEM.POINT with a declared subsystem "
                       f"({[s.name for s in subs]}), got {echo(ref)}")
        s = match[0]
        pts = s.points if s.type == "rigid" else s.ports
        if pname not in pts:
            t.error(k, f"names no point of subsystem `{sname}`; its points are {sorted(pts)}")
        return sname, pname

    a, b = port("a"), port("b")
    if a[0] == b[0]:
        t.error("b", f"must be on another subsystem than `a`, got {echo(a[0])} twice")
    law_t = t.table("law", section="law.linear")
    provide(CONTACT_LAWS, "cosim.laws", law_t.data.get("type"))
    law_name = law_t.string("type", choices=CONTACT_LAWS)
    law_t.use(f"law.{law_name}")
    law_cls = CONTACT_LAWS[law_name]
    params = {}
    for f in dataclasses.fields(law_cls):
        if f.name in law_t.data:
            params[f.name] = law_t.number(f.name)
        elif f.default is dataclasses.MISSING:
            why = f.metadata.get("required")     # a law may say why no default would do
            law_t.error(f.name, f"is required by law `{law_name}`" + (f": {why}" if why else "")
                        + law_t.misspelt(f.name))
    law_t.finish()
    law = build_model(law_t, law_cls, **params)
    if type(law).__module__.split(".")[0] != "couplers":   # a plug-in's? judged once
        from cosim.core.plugin_guard import check_law
        check_law(law)
    kinds = {s.name: s.type for s in subs}
    structures = {s.name for s in subs if isinstance(s, StructureSpec)}
    rigid_side = kinds[a[0]] == "rigid" or kinds[b[0]] == "rigid"
    if kinds[a[0]] == "rigid" and kinds[b[0]] == "rigid":
        t.error("b", "a contact between two rigid subsystems has nothing to simulate")
    placement = t.string("placement", "embedded" if rigid_side or t.has("radius") else "coupler",
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
    follow = t.boolean("follow")
    if follow and kinds[b[0]] not in ("beam", "cable", "string", "rod", "plane"):
        what = (f"a {kinds[b[0]]} (a point follows a beam, cable, string, rod or a plane "
                f"body's boundary)" if b[0] not in structures else
                f"a `{kinds[b[0]]}`, which an installed package declares; a contact follows "
                f"the built-in beam, cable, string, rod or plane body")
        t.error("follow", f"moves side b's point along a line structure; `{b[0]}` is {what}")
    if follow and host == a[0]:
        # the surface point slides along b as a moves: only b's integrator
        # applies the force along the surface's slope that this brings
        t.error("host", f"must be {echo(b[0])}, the structure whose surface a following contact "
                        f"(`follow = true`) follows: hosted by `{a[0]}`, point a's side, it "
                        f"would miss the surface's slope force, got {echo(host)}; leave `host` "
                        f"out (a following contact is hosted by its structure), or set "
                        f"`follow = false`")
    connection = _connection(t, law)
    radius = None
    if t.has("radius"):         # a circle's rules come first (loaded only for a circle)
        from cosim.scene.circle_rules import circle_radius
        radius = circle_radius(t, a, b, kinds, law, placement, host, follow, connection)
    if connection is not None and placement == "embedded" and (
            a[0] in structures or b[0] in structures):
        t.error("placement", "a grasp or friction against a rigid side is not evaluated inside "
                             "a structure; set placement `coupler`")
    if connection is not None and placement == "embedded" and not rigid_side:
        t.error("placement", "a grasp or friction between two moving sides is exchanged by the "
                             "scheme, not hosted by one side; set placement `coupler`")
    spec = ContactSpec(name=name, key=t.key(), a=a, b=b,
                       normal=t.vec2("normal", unit="1", nonzero=True), follow=follow,
                       offset=t.number("offset", unit="m"), law=law, placement=placement,
                       host=host, connection=connection, radius=radius)
    t.finish()
    return spec


def _trigger(t: Table, k: str, release: bool):
    """``close`` or ``release`` of a grasp (see :class:`couplers.Trigger`)."""
    from couplers import Trigger
    forms = _RELEASE_FORMS if release else _TRIGGER_FORMS
    v = t.raw(k)
    if isinstance(v, str):
        if release or v not in ("start", "touch"):
            t.error(k, f"must be {forms}, got {echo(v)}")
        return Trigger(v)
    if not isinstance(v, dict):
        t.error(k, f"must be {forms}, got {type_name(v)} {echo(v)}")
    tt = t.table(k, section="trigger")
    if tt.has("time") == tt.has("after"):
        tt.error("", f"must be {forms}: give one of `time` and `after`, got {echo(v)}")
    if tt.has("time"):
        trig = Trigger("time", time=tt.number("time", rule=">=0", unit="s"))
    else:
        event = tt.string("after")
        cname, _, what = event.rpartition(".")
        if not cname or what not in ("grasp", "release"):
            tt.error("after", f"must read CONTACT.grasp or CONTACT.release, got {echo(event)}")
        trig = Trigger("after", event=event, delay=tt.number("delay", rule=">=0", unit="s"))
    tt.finish()
    return trig


def _connection(t: Table, law):
    """A contact's ``grasp`` and ``friction`` tables, or None when it has neither
    (a friction coefficient of 0 builds no friction)."""
    if not (t.has("grasp") or t.has("friction")):
        return None                  # couplers.connection loads for the contacts that need it
    from couplers import Connection, Friction, Grasp
    grasp = close = release = friction = None
    if t.has("grasp"):
        gt = t.table("grasp", section="grasp")
        if law.rigid:
            t.error("grasp", "needs a penalty law: a `rigid` law is an impulse, it cannot hold")
        params = {k: gt.number(k, rule=">0" if k == "stiffness" else ">=0", unit=unit)
                  for k, unit in (("stiffness", "N/m"), ("damping", "N s/m"),
                                  ("tangential_stiffness", "N/m"),
                                  ("tangential_damping", "N s/m"))}
        grasp = build_model(gt, Grasp, **params)
        if not gt.has("close"):
            gt.error("close", f"is required: when the grasp closes, {_TRIGGER_FORMS}")
        close = _trigger(gt, "close", release=False)
        release = _trigger(gt, "release", release=True) if gt.has("release") else None
        gt.used.add("release")
        if (close.kind == "time" and release is not None and release.kind == "time"
                and release.time <= close.time):
            gt.error("release", f"time {echo(release.time)} s must come after the close time "
                                f"{echo(close.time)} s")
        gt.finish()
    if t.has("friction"):
        ft = t.table("friction", section="friction")
        if law.rigid:
            t.error("friction", "does not apply to a `rigid` law, which has its own Coulomb "
                                "friction in impulse space (`law.friction`)")
        mu = ft.number("coefficient", rule=">=0", unit="1")
        if mu > 0:
            friction = build_model(ft, Friction, coefficient=mu,
                                   slip_velocity=ft.number("slip_velocity", rule=">0",
                                                           unit="m/s"))
        else:
            ft.number("slip_velocity", None, rule=">0", unit="m/s")
        ft.finish()
    if grasp is None and friction is None:
        return None
    return Connection(grasp, friction, close, release)


def check_conditions(contacts: list, file) -> None:
    """Every ``after`` names an event of a contact that can have it."""
    grasps = {c.name for c in contacts
              if c.connection is not None and c.connection.grasp is not None}
    for c in contacts:
        conn = c.connection
        if conn is None or conn.grasp is None:
            continue
        for which, trig in (("close", conn.close), ("release", conn.release)):
            if trig is None or trig.kind != "after":
                continue
            other = trig.event.rpartition(".")[0]
            key = f"{c.key}.grasp.{which}.after"
            if other not in grasps:
                raise SceneError(file, key, f"names {echo(trig.event)}, but no contact named "
                                            f"`{other}` has a grasp; contacts with a grasp are "
                                            f"{sorted(grasps)}")
            if which == "close" and other == c.name:
                raise SceneError(file, key, f"cannot wait for an event of its own grasp, got "
                                            f"{echo(trig.event)}")
