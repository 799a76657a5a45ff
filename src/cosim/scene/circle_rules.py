"""A contact's ``radius`` (a circle against a plane body): the loader's
checks of the key and the builder's rules of what a circle runs with
(:mod:`cosim.sides.plane_circle` hosts it, :mod:`cosim.core.circles` couples
it).  It imports nothing of the scene package but its error helpers.

A circle of radius ``radius`` centred on side a's point (the robot's)
presses the plane body of side b where its boundary lies inside the
circle; its law is ``linear`` with ``contact_stiffness`` read as the
pressure per metre of penetration [Pa/m].  The body hosts it; the
Gauss-Seidel scheme hands the force on the circle, a vector through its
centre, to side a after the body's step.
"""
from __future__ import annotations

from cosim.scene.checks import SceneError, echo

__all__ = ["circle_radius", "circle_build_rules", "CIRCLE_SCHEMES"]

#: the schemes that run a circle contact
CIRCLE_SCHEMES = ("gauss_seidel",)


def circle_radius(t, a: tuple, b: tuple, kinds: dict, law, placement: str, host,
                  follow: bool, connection):
    """The ``radius`` [m] of contact table ``t``, or None when it has none;
    refused (at the key that does not fit) where a circle cannot run.
    ``a``, ``b`` are its ``(subsystem, point)``; ``kinds`` each subsystem's
    type."""
    radius = t.number("radius", rule=">0", unit="m")
    if radius is None:
        return None
    if kinds[b[0]] != "plane":
        t.error("radius", f"makes a circle that presses a plane body: side b must be a plane "
                          f"body (`type = \"plane\"`), and `{b[0]}` is a {kinds[b[0]]}; put the "
                          f"circle's centre at a and the body at b")
    if kinds[a[0]] in ("plane", "rigid"):
        t.error("radius", f"centres the circle on side a's point, which must move with "
                          f"another body than a plane one (a multibody or a structure's point); "
                          f"`{a[0]}` is a {kinds[a[0]]}")
    if law.name != "linear":
        t.error("law", f"of a circle (`radius`) must be `linear`, its `contact_stiffness` the "
                       f"pressure per metre of penetration [Pa/m]; got `{law.name}`")
    if placement != "embedded":
        t.error("placement", f"of a circle (`radius`) must be `embedded`: the plane body "
                             f"integrates its spread penalty in its own step; got "
                             f"{echo(placement)}")
    if host is not None and host != b[0]:
        t.error("host", f"of a circle (`radius`) must be the plane body {echo(b[0])}, which "
                        f"integrates its spread penalty, got {echo(host)}")
    if follow:
        t.error("follow", "does not apply to a circle (`radius`), which finds the boundary "
                          "inside it wherever it is; set `follow = false`")
    if connection is not None:
        t.error("grasp" if t.has("grasp") else "friction",
                "is not supported on a circle (`radius`): a circle presses, frictionless")
    return radius


def circle_build_rules(scene, scheme: str, system, contact, order: list) -> None:
    """Refuse (SceneError at the key) a scene a circle contact cannot run
    in: another scheme than Gauss-Seidel, the plane body not stepping
    before the circle's side (``order``: the names of the moving
    subsystems in the order the scheme steps them), the body's static
    correction or structural integrator (a point contact's, a modal
    step's), or a multirate partner."""
    body, robot = contact.b[0], contact.a[0]
    if scheme not in CIRCLE_SCHEMES:
        raise SceneError(scene.path, "scheme.name",
                         f"contact `{contact.name}` is a circle (`radius`), which runs with "
                         f"scheme {' or '.join(f'`{s}`' for s in CIRCLE_SCHEMES)} only (the "
                         f"body steps first and hands the force vector on); got `{scheme}`")
    if order.index(body) > order.index(robot):
        raise SceneError(scene.path, "scheme.sequence",
                         f"must step the plane body `{body}` before `{robot}`: contact "
                         f"`{contact.name}` is a circle the body integrates, and `{robot}` "
                         f"receives the force of the body's step; the order is {order}")
    spec = next(s for s in scene.subsystems if s.name == body)
    if spec.static_correction:
        raise SceneError(scene.path, f"{spec.key}.modes.static_correction",
                         f"corrects a point contact; contact `{contact.name}` is a circle "
                         f"(`radius`) spread over the boundary: turn the correction off")
    sub = system.subsystems[system.names.index(body)]
    if getattr(sub, "integrator", "exact") != "exact":
        raise SceneError(scene.path, f"{spec.key}.integrator.method",
                         f"steps the modes by `{sub.integrator}`; a body hosting circle "
                         f"`{contact.name}` takes the exact modal step between contacts: "
                         f"leave the method out")
