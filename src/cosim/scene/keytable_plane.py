"""The keys of a plane body's tables (``type = "plane"``), a part of the
table of scene keys: :mod:`cosim.scene.keytable` calls :func:`plane_sections`
with its own key and section classes and adds what it returns to its
``SECTIONS`` (this module imports nothing of cosim's)."""
from __future__ import annotations

__all__ = ["plane_sections", "circle_keys"]

_TABLE = "a table"
_VEC = "two finite numbers"


def circle_keys(K) -> tuple:
    """The key of ``[contacts.NAME]`` that makes a contact a circle against
    a plane body (:mod:`cosim.scene.circle_rules` reads it)."""
    return (K("radius", "m", None, "> 0; a at the circle's centre, b on a plane body",
              "a circle of this radius centred on a's point presses b's boundary where it lies "
              "inside it (law `linear`, its `contact_stiffness` in Pa/m: pressure per metre "
              "of penetration; hosted by the plane body, scheme `gauss_seidel`)"),)


def plane_sections(K, Section, REQUIRED, subsystem_type, common: tuple) -> dict:
    """Section id -> section of a plane body's tables, made of ``K`` (the
    key class), ``Section``, ``REQUIRED``, the ``type`` key and the keys
    ``common`` to every structure."""
    return {sid: Section(path, 'type = "plane"', keys)
            for sid, (path, keys) in _plane_keys(K, REQUIRED, subsystem_type, common).items()}


def _plane_keys(K, REQUIRED, subsystem_type, common: tuple) -> dict:
    body = (
        subsystem_type,
        K("mesh", "", REQUIRED, "a mesh file meshio reads (Gmsh .msh 2.2 or 4.1, .xdmf, .vtu), "
          "relative to the scene; first-order triangles or quadrangles in z = 0",
          "the body's mesh, its boundary groups from Gmsh's physical curves"),
        K("scale", "m", 1.0, "> 0", "the mesh's length unit in metres (0.001 for millimetres)"),
        K("model", "", "plane_stress", '"plane_stress" or "plane_strain"', "the plane model"),
        K("thickness", "m", REQUIRED, "> 0", "thickness out of the plane"),
        K("youngs_modulus", "Pa", REQUIRED, "> 0", "Young's modulus"),
        K("poisson_ratio", "", REQUIRED, "in [0, 0.5)", "Poisson's ratio"),
        K("density", "kg/m^3", REQUIRED, "> 0", "density"),
        K("element", "", "P2", '"P1", "P2" (triangles), "Q1" or "Q2" (quadrangles)',
          "the finite element"),
        K("supports", "", {}, _TABLE, "which boundary groups are held (none: a free body)"),
        K("origin", "m", (0.0, 0.0), _VEC, "world position of the mesh's origin"),
        K("angle", "rad", 0.0, "a finite number", "rotation of the mesh into the world"),
    ) + tuple(k for k in common if k.name not in ("modes", "initial_velocity")) + (
        K("modes", "", {}, _TABLE, "which modes are kept, and the static correction"),
        K("initial_velocity", "m/s", (0.0, 0.0), _VEC, "uniform initial velocity (world)"),
    )
    groups = "a group of the mesh (a physical curve or point) or an array of them"
    supports = (
        K("fixed", "", None, groups, "groups whose displacement is zero"),
        K("fixed_x", "", None, groups, "groups whose displacement along the mesh's x is zero"),
        K("fixed_y", "", None, groups, "groups whose displacement along the mesh's y is zero"),
    )
    points = (K("POINT", "", REQUIRED, "a table `{ boundary = GROUP, s = ARC }`",
                 "a point on the boundary"),)
    point = (
        K("boundary", "", REQUIRED, "a boundary group of the mesh: one chain of curves",
          "the group the point lies on"),
        K("s", "m", None, "in [0, the group's length]; not set: a straight group's average",
          "arc length along the group, from the free end of its first line cell in the file; "
          "not set, the group's mean normal displacement (a force on it: uniform traction)"),
    )
    modes = (
        K("count", "", None, "an integer >= 1", "keep the lowest `count` modes"),
        K("cutoff_hz", "Hz", None, "> 0", "keep the modes below this frequency"),
        K("static_correction", "", False, "true or false; linear contact laws only",
          "add the dropped modes' static compliance in series with each contact's spring"),
        K("cache", "", None, "a folder, relative to the scene",
          "keep the modes there, keyed on the mesh's content, material, supports and modes"),
    )
    return {
        "plane": ("subsystems.NAME", body),
        "plane.supports": ("subsystems.NAME.supports", supports),
        "plane.points": ("subsystems.NAME.points", points),
        "plane.point": ("subsystems.NAME.points.POINT", point),
        "plane.modes": ("subsystems.NAME.modes", modes),
    }
