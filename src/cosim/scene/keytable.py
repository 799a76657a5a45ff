"""The table of scene keys, as data: one :class:`Section` per table of a
scene file, one :class:`Key` per key it accepts (unit, default or required,
check, meaning).

:mod:`cosim.scene.keys` adds the sections made from registries (the
schemes' options, the laws' parameters) and renders the whole as Markdown;
:class:`cosim.scene.checks.Table` reads scene tables against it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from cosim.core.guard import (DEFAULT_CHATTER_SWITCHES, DEFAULT_CHATTER_WINDOW,
                              DEFAULT_COUPLING_WARNING, DEFAULT_ENERGY_FLOOR,
                              DEFAULT_ENERGY_GROWTH, DEFAULT_ENERGY_WARNING)
from cosim.io.rundir import NAME_MAX
from cosim.scene.keytable_plane import circle_keys, plane_sections

__all__ = ["Key", "Section", "SECTIONS", "REQUIRED", "Varies", "DEFAULT_MULTIBODY_STEP",
           "DEFAULT_CONTACT_STEP", "STRUCTURE_TYPES", "SUBSYSTEM_TYPES", "NAME_TEXT",
           "MAX_STEPS"]

#: the ``type`` of a structure subsystem
STRUCTURE_TYPES = ("chain", "beam", "cable", "string", "rod", "plane")
#: every ``type`` a subsystem may have (the loader's choices, the table's text)
SUBSYSTEM_TYPES = ("multibody", "rigid", "fmu") + STRUCTURE_TYPES

#: [s] the step of a multibody side's ``rk4`` when the scene gives no
#: ``integrator.max_step``: the macro step when it is shorter, else this.
#: It resolves the contact of the reference scene (spring_drop: 10^6 N/m on
#: 1 kg, omega = 1000 rad/s) with omega * dt = 0.1, about 31 steps over the
#: pi / omega = 3.1 ms that the contact lasts, well inside the bound
#: omega * dt <= sqrt(2) (half of RK4's stability limit) that the builder
#: demands of an embedded contact; a stiffer contact is refused when the
#: scene is built, naming ``integrator.max_step``.
DEFAULT_MULTIBODY_STEP = 1e-4
#: [s] default RK4 step of a structure while a contact it hosts is closed
DEFAULT_CONTACT_STEP = 1e-6
#: most integrator steps a run may take unless the scene's ``guard.max_steps``
#: raises it (counted before the run, :mod:`cosim.scene.work`)
MAX_STEPS = 10**9


class _Required:
    def __repr__(self):
        return "REQUIRED"


#: the default of a key that must be given
REQUIRED = _Required()


@dataclass(frozen=True)
class Varies:
    """A default that depends on the rest of the scene; ``text`` says how
    (the loader passes the value it computes)."""

    text: str


@dataclass(frozen=True)
class Key:
    """One key of a scene table.

    Attributes
    ----------
    name : str
        The key; upper case (``POINT``) for a name the scene chooses.
    unit : str
        SI unit of its value ("" for none).
    default : object
        Its value when absent: :data:`REQUIRED`, a :class:`Varies`, ``None``
        (not set: the feature is off) or a value.
    check : str
        What a value must be.
    meaning : str
        One line on what it does.
    """

    name: str
    unit: str
    default: object
    check: str
    meaning: str

    @property
    def placeholder(self) -> bool:
        """True for a name the scene chooses (``POINT``)."""
        return self.name.isupper()


@dataclass(frozen=True)
class Section:
    """One table of a scene file.

    Attributes
    ----------
    path : str
        Its key path (``contacts.NAME.grasp``; "" for the top level).
    when : str
        The condition under which these keys apply (``type = "beam"``), or "".
    keys : tuple of Key
    """

    path: str
    when: str
    keys: tuple

    def __post_init__(self):
        object.__setattr__(self, "_index", {k.name: k for k in self.keys})
        object.__setattr__(self, "_placeholder",
                           next((k for k in self.keys if k.placeholder), None))

    def find(self, name: str) -> Key | None:
        """The key ``name``, or the placeholder key that stands for it, or None."""
        return self._index.get(name, self._placeholder)

    @property
    def names(self) -> list[str]:
        """The names of its keys, placeholders excluded."""
        return [k.name for k in self.keys if not k.placeholder]

    @property
    def title(self) -> str:
        where = f"[{self.path}]" if self.path else "top level"
        return f"{where} with {self.when}" if self.when else where


K = Key
_TABLE = "a table"
_VEC = "two finite numbers"
_UNIT_VEC = "two finite numbers, not both 0"
#: the rule of :func:`cosim.io.rundir.name_problem`, which the loader applies to
#: every name that becomes a folder, a file or a key (``check_name``)
NAME_TEXT = (f"a plain name: 1 to {NAME_MAX} of `A-Z a-z 0-9 _ . + -`, not starting with "
             f"`.`, `+` or `-`, without `..`")
_WORD = NAME_TEXT


def _types(*names: str) -> str:
    return ", ".join(f'"{n}"' for n in names)


# ------------------------------------------------------------ the sections
_TOP = (
    K("name", "", Varies("the file's name without `.toml`"), _WORD,
      "the scene's name: the run folder's default name"),
    K("description", "", "", "a string", "what the scene shows, for people"),
    K("t_end", "s", REQUIRED, "> 0", "end time of the run"),
    K("default_variant", "", None, "the name of a variant",
      "the variant applied when none is chosen (`--variant`)"),
    K("variants", "", {}, "a table of tables", "named tables of overrides (`[variants.NAME]`)"),
    K("scheme", "", REQUIRED, _TABLE, "the coupling scheme and its options"),
    K("output", "", {}, _TABLE, "what the run records"),
    K("effects", "", {}, _TABLE, "effects on every subsystem (gravity)"),
    K("guard", "", {}, _TABLE, "when the run guard stops or warns"),
    K("subsystems", "", REQUIRED, "a table of at least one subsystem", "the sides of the scene"),
    K("contacts", "", {}, _TABLE, "the contacts between two points of two subsystems"),
)

_OUTPUT = (
    K("every", "", 1, "an integer >= 1", "record every n-th accepted step"),
    K("export", "", [], "a list of structure names",
      "structures whose fields are written as `NAME.xdmf` (needs meshio)"),
    K("export_every", "", 1, "an integer >= 1", "export every n-th recorded sample"),
    K("estimate", "", True, "true or false",
      "`cosim run` estimates the run's error from two companion runs at 0.71 and 1.41 times "
      "the step "
      "(summary key `accuracy`)"),
)

_EFFECTS = (
    K("gravity", "m/s^2", None, "> 0 (downward), or [gx, gy] of two finite numbers",
      "gravitational acceleration on every body and structure"),
)

_GUARD = (
    K("energy_growth", "", DEFAULT_ENERGY_GROWTH, "> 0",
      "stop when the energy created exceeds this times the energy scale"),
    K("energy_check", "", True, "true or false", "whether created energy stops a run"),
    K("energy_floor", "J", DEFAULT_ENERGY_FLOOR, ">= 0",
      "created energy below this never stops or warns"),
    K("energy_warning", "", DEFAULT_ENERGY_WARNING, "> 0",
      "warn when the energy created exceeds this times the energy scale"),
    K("coupling_warning", "", DEFAULT_COUPLING_WARNING, "> 0",
      "warn when a contact's coupling error exceeds this times the energy scale"),
    K("chatter_switches", "", DEFAULT_CHATTER_SWITCHES, "an integer in [2, 10^9]",
      "switches of one contact within the chatter window that stop a run"),
    K("chatter_window", "s", DEFAULT_CHATTER_WINDOW, ">= 0",
      "simulated time over which switches are counted"),
    K("max_steps", "", MAX_STEPS, "> 0",
      "most integrator steps (all sides, every iteration) a run may take, counted before it "
      "starts; a run counted above is refused"),
)

_SUBSYSTEM_TYPE = K("type", "", REQUIRED, "one of " + _types(*SUBSYSTEM_TYPES)
                    + ", or a structure an installed package declares (`cosim.structures`)",
                    "what the subsystem is")

_MULTIBODY = (
    _SUBSYSTEM_TYPE,
    K("integrator", "", {}, _TABLE, "the integrator of the multibody side"),
    K("bodies", "", REQUIRED, "a table of at least one body",
      "the bodies, each with the joint to its parent, parents first"),
)

_MULTIBODY_INTEGRATOR = (
    K("method", "", "rk4", 'one of "rk4", "rk45", "dop853", "radau", "bdf"',
      "the integrator of the joint coordinates"),
    K("max_step", "s", Varies(f"rk4: the macro step, at most {DEFAULT_MULTIBODY_STEP:g} s; "
                              "adaptive methods: not set"), "> 0",
      "the (largest) integrator step"),
    K("rtol", "", None, ">= 2.22e-14 (100 eps); adaptive methods only", "relative tolerance"),
    K("atol", "", None, "> 0; adaptive methods only", "absolute tolerance"),
    K("free_step", "s", None, "> 0; rk4 only",
      "a longer rk4 step while no contact the side hosts is closed"),
)

_BODY = (
    K("mass", "kg", REQUIRED, ">= 0", "the body's mass"),
    K("inertia", "kg m^2", 0.0, ">= 0", "moment of inertia about the centre of mass"),
    K("com", "m", (0.0, 0.0), _VEC, "centre of mass in the body frame"),
    K("points", "", {}, _TABLE, "named points of the body (contact ports)"),
    K("joint", "", REQUIRED, _TABLE, "the joint that connects the body to its parent"),
)

_BODY_POINTS = (K("POINT", "m", REQUIRED, _VEC + "; unique in the subsystem",
                  "a point in the body frame"),)

_JOINT = (
    K("name", "", REQUIRED, _WORD + "; unique in the subsystem",
      "the joint's name (`final_state`, `q/SUBSYSTEM/NAME` series)"),
    K("type", "", REQUIRED, '"revolute" or "prismatic"', "rotation or sliding"),
    K("parent", "", "ground", "`ground` or a body declared before", "the body it hangs from"),
    K("offset", "m", (0.0, 0.0), _VEC, "the joint's place in the parent's frame"),
    K("axis", "", (1.0, 0.0), _UNIT_VEC, "sliding direction of a prismatic joint"),
    K("angle", "rad", 0.0, "a finite number", "fixed rotation of the body frame"),
    K("q0", "m or rad", 0.0, "a finite number", "initial joint coordinate"),
    K("dq0", "m/s or rad/s", 0.0, "a finite number", "initial joint velocity"),
    K("spring", "", None, _TABLE, "a spring on the joint"),
    K("damper", "", None, _TABLE, "a damper on the joint"),
    K("drive", "", None, _TABLE, "a drive (torque or force) on the joint"),
)

_SPRING = (
    K("stiffness", "N m/rad or N/m", REQUIRED, ">= 0", "spring constant"),
    K("rest", "rad or m", 0.0, "a finite number", "joint coordinate where the spring is slack"),
)
_DAMPER = (K("damping", "N m s/rad or N s/m", REQUIRED, ">= 0", "viscous damping"),)

_DRIVE_TYPE = K("type", "", REQUIRED, '"constant", "table" or "pd"', "the kind of drive")
_DRIVE = {
    "constant": (_DRIVE_TYPE,
                 K("torque", "N m or N", REQUIRED, "a finite number", "the constant torque")),
    "table": (_DRIVE_TYPE,
              K("times", "s", REQUIRED, "a non-empty array of increasing times",
                "the times of the table"),
              K("torques", "N m or N", REQUIRED, "an array as long as `times`",
                "torque at each time, linear between, held outside")),
    "pd": (_DRIVE_TYPE,
           K("kp", "N m/rad or N/m", REQUIRED, ">= 0", "proportional gain"),
           K("kd", "N m s/rad or N s/m", REQUIRED, ">= 0", "derivative gain"),
           K("reference", "", REQUIRED, _TABLE, "the trajectory the joint tracks"),
           K("max_torque", "N m or N", math.inf, "> 0", "saturation of the drive")),
}

_REFERENCE_TYPE = K("type", "", REQUIRED, _types("table", "minimum_jerk", "sinusoid"),
                    "the kind of trajectory")
_REFERENCE = {
    "table": (_REFERENCE_TYPE,
              K("times", "s", REQUIRED, "a non-empty array of increasing times",
                "the times of the table"),
              K("values", "rad or m", REQUIRED, "an array as long as `times`",
                "the reference at each time, linear between")),
    "minimum_jerk": (_REFERENCE_TYPE,
                     K("start", "rad or m", REQUIRED, "a finite number", "value before `t_start`"),
                     K("end", "rad or m", REQUIRED, "a finite number", "value after `t_end`"),
                     K("t_start", "s", REQUIRED, "a finite number", "start of the motion"),
                     K("t_end", "s", REQUIRED, "> `t_start`", "end of the motion")),
    "sinusoid": (_REFERENCE_TYPE,
                 K("amplitude", "rad or m", REQUIRED, "a finite number", "amplitude"),
                 K("frequency", "Hz", REQUIRED, "a finite number", "frequency"),
                 K("phase", "rad", 0.0, "a finite number", "phase at t = 0"),
                 K("offset", "rad or m", 0.0, "a finite number", "mean value")),
}

_FMU = (
    _SUBSYSTEM_TYPE,
    K("path", "", REQUIRED, "an existing co-simulation .fmu file (FMI 2.0 or 3.0), relative to "
      "the scene file, whose `modelIdentifier` is a C identifier and whose variable names are "
      "unique", "the Functional Mock-up Unit (cosim.sides.fmu)"),
    K("ports", "", REQUIRED, "a table of at least one port", "the FMU's contact ports"),
    K("parameters", "", {}, _TABLE, "start values of the FMU's parameters, set before it is "
      "initialised"),
    K("coordinates", "", {}, _TABLE, "named coordinates recorded as `q/SUBSYSTEM/NAME` series"),
    K("energy", "J", None, "an output variable of the FMU",
      "its mechanical energy; required while the run guard checks energy"),
)
_FMU_PORTS = (K("PORT", "", REQUIRED, _TABLE, "a port: the variables of a point of the FMU"),)
_FMU_PORT = (
    K("position", "m", REQUIRED, "two different output variables", "the point's x and y"),
    K("velocity", "m/s", REQUIRED, "two different output variables, not the position's",
      "the point's velocity"),
    K("force", "N", REQUIRED, "two different input variables that no other key sets",
      "the contact force the FMU receives"),
    K("port_mass", "kg", REQUIRED, "> 0 with a finite inverse, or the name of an output "
      "variable whose value after initialisation is",
      "the mass the contact sees at the port (pre-flight check, host choice)"),
)
_FMU_PARAMETERS = (K("NAME", "", REQUIRED, "a finite number; a parameter of the FMU that no "
                     "other key sets",
                     "its start value"),)
_FMU_COORDINATES = (K("NAME", "", REQUIRED, "two different output variables; NAME "
                      + NAME_TEXT,
                      "[position, velocity] of a coordinate"),)

_RIGID = (
    _SUBSYSTEM_TYPE,
    K("points", "", REQUIRED, "a table of at least one point", "the fixed points"),
)
_RIGID_POINTS = (K("POINT", "m", REQUIRED, _VEC, "a fixed point in the world frame"),)

_COMMON_STRUCTURE = (
    K("rayleigh", "1/s, s", None, "[a0, a1] of numbers >= 0",
      "Rayleigh damping C = a0 M + a1 K"),
    K("points", "", REQUIRED, "a table of at least one point", "named material points (ports)"),
    K("modes", "", {}, _TABLE, "which modes are kept"),
    K("integrator", "", {}, _TABLE, "the structural integrator"),
    K("initial_velocity", "m/s", 0.0, "a finite number; 0 for a beam or cable",
      "uniform initial velocity along `direction`"),
    K("static_equilibrium", "", False, "true or false",
      "start at the static state under gravity and `static_loads`"),
    K("static_loads", "", None, "a table; needs `static_equilibrium = true`",
      "point loads of the static state"),
)
_LINE = (
    K("length", "m", REQUIRED, "> 0", "length"),
    K("density", "kg/m^3", REQUIRED, "> 0", "density"),
    K("elements", "", REQUIRED, "an integer in [1, MAX_ELEMENTS]", "number of finite elements"),
    K("origin", "m", (0.0, 0.0), _VEC, "position of the start (s = 0)"),
    K("axis", "", (1.0, 0.0), _UNIT_VEC, "direction along the structure"),
)
_DIRECTION = K("direction", "", (0.0, 1.0), _UNIT_VEC + "; across `axis` for a line",
               "direction of the displacement field")
_ENDS = 'one of "pinned", "clamped", "free", "sliding"'

_STRUCTURES = {
    "chain": (
        _SUBSYSTEM_TYPE,
        K("masses", "kg", REQUIRED, "a non-empty array of numbers > 0 (at most MAX_ELEMENTS)",
          "the masses, from the ground up"),
        K("stiffnesses", "N/m", REQUIRED, "an array of numbers > 0, one per spring",
          "the springs between neighbours (and to the ground)"),
        K("ground_below", "", True, "true or false", "a spring ties the first mass to the ground"),
        K("spacing", "m", REQUIRED, "> 0", "distance between neighbouring masses"),
        K("origin", "m", (0.0, 0.0), _VEC, "position of the first mass"),
        _DIRECTION,
    ) + _COMMON_STRUCTURE,
    "beam": (_SUBSYSTEM_TYPE,) + _LINE + (
        K("youngs_modulus", "Pa", REQUIRED, "> 0", "Young's modulus"),
        K("section", "", REQUIRED, _TABLE, "the cross-section"),
        K("left", "", REQUIRED, _ENDS, "boundary condition at s = 0"),
        K("right", "", REQUIRED, _ENDS, "boundary condition at s = length"),
        K("tension", "N", Varies("0 for a beam; required for a cable"),
          ">= 0 (beam), > 0 (cable)", "axial tension (geometric stiffness)"),
        _DIRECTION,
    ) + _COMMON_STRUCTURE,
    "string": (_SUBSYSTEM_TYPE,) + _LINE + (
        K("tension", "N", REQUIRED, "> 0", "tension"),
        K("area", "m^2", REQUIRED, "> 0", "cross-section area"),
        _DIRECTION,
    ) + _COMMON_STRUCTURE,
    "rod": (_SUBSYSTEM_TYPE,) + _LINE + (
        K("youngs_modulus", "Pa", REQUIRED, "> 0", "Young's modulus"),
        K("area", "m^2", REQUIRED, "> 0", "cross-section area"),
        K("left", "", "free", '"fixed" or "free"', "boundary condition at s = 0"),
        K("right", "", "free", '"fixed" or "free"', "boundary condition at s = length"),
    ) + _COMMON_STRUCTURE,
}

_SECTION = (
    K("diameter", "m", None, "> 0", "diameter of a circular section"),
    K("width", "m", Varies("required without `diameter`"), "> 0",
      "width of a rectangular section"),
    K("height", "m", Varies("required without `diameter`"), "> 0",
      "height of a rectangular section (along `direction`)"),
)
_STRUCTURE_POINTS = (K("POINT", "m", REQUIRED, "in [0, length]; a mass index 0..n-1 for a chain",
                       "a material coordinate along the structure"),)
_MODES = (
    K("count", "", None, "an integer >= 1", "keep the lowest `count` modes"),
    K("cutoff_hz", "Hz", None, "> 0", "keep the modes below this frequency"),
)
_STRUCTURE_INTEGRATOR = (
    K("method", "", "exact",
      _types("newmark", "hht_alpha", "generalized_alpha", "central_difference", "exact"),
      "how the modal coordinates are stepped"),
    K("contact_step", "s", DEFAULT_CONTACT_STEP, "> 0",
      "RK4 step while a contact the structure hosts is closed"),
    K("beta", "", None, ">= 0 (newmark)", "Newmark's beta (0.25 when not set)"),
    K("gamma", "", None, ">= 1/2 (newmark)", "Newmark's gamma (0.5 when not set)"),
    K("alpha", "", None, "in [-1/3, 0] (hht_alpha)", "HHT's alpha (-0.05 when not set)"),
    K("rho_inf", "", None, "in [0, 1] (generalized_alpha)",
      "spectral radius at infinite frequency (0.8 when not set)"),
)
_STATIC_LOADS = (K("POINT", "N", REQUIRED, "a finite number; a point of the structure",
                   "force along `direction` at that point"),)

_CONTACT = (
    K("a", "", REQUIRED, "SUBSYSTEM.POINT of a declared subsystem", "side a's point"),
    K("b", "", REQUIRED, "SUBSYSTEM.POINT on another subsystem", "side b's point"),
    K("law", "", REQUIRED, _TABLE, "the contact law"),
    K("placement", "", Varies('"embedded" with a rigid side or a `radius`, else "coupler"'),
      '"embedded" or "coupler"',
      "who evaluates the contact: one side's integrator or the scheme"),
    K("host", "", Varies("the lighter side; with `follow`, the subsystem of `b`"),
      "the subsystem of `a` or of `b`; of `b` with `follow`",
      "the side that integrates an embedded contact between two moving sides"),
    K("follow", "", False, "true or false; b on a line structure or a plane body",
      "move b's point along the structure with a's point, or along a plane body's boundary "
      "to the point closest to a's (an embedded contact is then hosted by b's structure)"),
    K("normal", "", REQUIRED, _UNIT_VEC, "contact normal, from b towards a"),
    K("offset", "m", 0.0, "a finite number", "gap added to the distance along the normal"),
    K("grasp", "", None, _TABLE, "a bilateral grasp that holds the two points"),
    K("friction", "", None, _TABLE, "regularised Coulomb friction"),
)
_GRASP = (
    K("stiffness", "N/m", REQUIRED, "> 0", "normal stiffness of the grasp"),
    K("damping", "N s/m", REQUIRED, ">= 0", "normal damping"),
    K("tangential_stiffness", "N/m", REQUIRED, ">= 0", "tangential stiffness"),
    K("tangential_damping", "N s/m", REQUIRED, ">= 0", "tangential damping"),
    K("close", "", REQUIRED, '"start", "touch", or a table with `time` or `after`',
      "when the grasp closes"),
    K("release", "", None, "a table with `time` or `after`", "when the grasp opens"),
)
_TRIGGER = (
    K("time", "s", Varies("give `time` or `after`"), ">= 0", "at this time"),
    K("after", "", Varies("give `time` or `after`"), "CONTACT.grasp or CONTACT.release",
      "after another grasp's event"),
    K("delay", "s", 0.0, ">= 0", "delay after the event named by `after`"),
)
_FRICTION = (
    K("coefficient", "", REQUIRED, ">= 0 (0 builds no friction)", "Coulomb coefficient"),
    K("slip_velocity", "m/s", Varies("required when `coefficient` > 0"), "> 0",
      "tangential speed at which friction reaches its full value"),
)

#: id -> section, the tables of a scene whose keys are fixed (the scheme
#: options and the law parameters come from their registries:
#: :func:`scheme_section`, :func:`law_section`)
SECTIONS: dict[str, Section] = {
    "top": Section("", "", _TOP),
    "variants": Section("variants", "", (K("NAME", "", REQUIRED, "a table of overrides",
                                           "a variant: keys as in the scene, merged into it"),)),
    "output": Section("output", "", _OUTPUT),
    "effects": Section("effects", "", _EFFECTS),
    "guard": Section("guard", "", _GUARD),
    "subsystems": Section("subsystems", "", (K("NAME", "", REQUIRED,
                                               _WORD + "; no `.` at all", "a subsystem"),)),
    "subsystem": Section("subsystems.NAME", "", (_SUBSYSTEM_TYPE,)),
    "multibody": Section("subsystems.NAME", 'type = "multibody"', _MULTIBODY),
    "multibody.integrator": Section("subsystems.NAME.integrator", 'type = "multibody"',
                                    _MULTIBODY_INTEGRATOR),
    "bodies": Section("subsystems.NAME.bodies", "", (K("BODY", "", REQUIRED, _TABLE,
                                                       "a body"),)),
    "body": Section("subsystems.NAME.bodies.BODY", "", _BODY),
    "body.points": Section("subsystems.NAME.bodies.BODY.points", "", _BODY_POINTS),
    "joint": Section("subsystems.NAME.bodies.BODY.joint", "", _JOINT),
    "spring": Section("subsystems.NAME.bodies.BODY.joint.spring", "", _SPRING),
    "damper": Section("subsystems.NAME.bodies.BODY.joint.damper", "", _DAMPER),
    **{f"drive.{t}": Section("subsystems.NAME.bodies.BODY.joint.drive", f'type = "{t}"', keys)
       for t, keys in _DRIVE.items()},
    **{f"reference.{t}": Section("subsystems.NAME.bodies.BODY.joint.drive.reference",
                                 f'type = "{t}"', keys)
       for t, keys in _REFERENCE.items()},
    "rigid": Section("subsystems.NAME", 'type = "rigid"', _RIGID),
    "fmu": Section("subsystems.NAME", 'type = "fmu"', _FMU),
    "fmu.ports": Section("subsystems.NAME.ports", 'type = "fmu"', _FMU_PORTS),
    "fmu.port": Section("subsystems.NAME.ports.PORT", 'type = "fmu"', _FMU_PORT),
    "fmu.parameters": Section("subsystems.NAME.parameters", 'type = "fmu"', _FMU_PARAMETERS),
    "fmu.coordinates": Section("subsystems.NAME.coordinates", 'type = "fmu"',
                               _FMU_COORDINATES),
    "rigid.points": Section("subsystems.NAME.points", 'type = "rigid"', _RIGID_POINTS),
    **{t: Section("subsystems.NAME", f'type = "{t}"' if t != "beam" else 'type = "beam" or "cable"',
                  keys) for t, keys in _STRUCTURES.items()},
    "section": Section("subsystems.NAME.section", 'type = "beam" or "cable"', _SECTION),
    "structure.points": Section("subsystems.NAME.points", "a structure", _STRUCTURE_POINTS),
    "modes": Section("subsystems.NAME.modes", "a structure", _MODES),
    "structure.integrator": Section("subsystems.NAME.integrator", "a structure",
                                    _STRUCTURE_INTEGRATOR),
    "static_loads": Section("subsystems.NAME.static_loads", "a structure", _STATIC_LOADS),
    "contacts": Section("contacts", "", (K("NAME", "", REQUIRED, _WORD, "a contact"),)),
    "contact": Section("contacts.NAME", "", _CONTACT + circle_keys(K)),
    "grasp": Section("contacts.NAME.grasp", "", _GRASP),
    "trigger": Section("contacts.NAME.grasp.close", "or `release`, as a table", _TRIGGER),
    "friction": Section("contacts.NAME.friction", "", _FRICTION),
}
SECTIONS["cable"] = SECTIONS["beam"]
SECTIONS.update(plane_sections(Key, Section, REQUIRED, _SUBSYSTEM_TYPE, _COMMON_STRUCTURE))
