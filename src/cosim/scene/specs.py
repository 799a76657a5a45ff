"""Typed scene specs: what the loader hands the builder.

:func:`cosim.scene.load.load_scene` reads and checks a scene file and returns
a :class:`Scene` of frozen specs (:class:`~cosim.scene.specs.MultibodySpec`,
:class:`~cosim.scene.specs.RigidSpec`, :class:`~cosim.scene.specs.StructureSpec`, :class:`~cosim.scene.specs.ContactSpec`); the
builder (:mod:`cosim.scene.build`) makes subsystems, contacts and a scheme of
them and reads nothing else.  Values are in SI, as validated; the scheme is
resolved in one place, :func:`~cosim.scene.specs.resolve_scheme`, into a :class:`~cosim.scene.specs.SchemeSpec`.

The loader imports this module and so does :meth:`Scene.build` the builder,
lazily; the loader and the builder never import each other.

A spec's fields are also read by key (``spec["law"]``), as the dictionaries
that the loader handed out before these classes were.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field
from typing import ClassVar

from cosim.core.guard import GuardOptions
from cosim.scene.checks import MAX_STEPS, SceneError
from cosim.scene.keys import DEFAULT_CONTACT_STEP, DEFAULT_MULTIBODY_STEP
# the subsystem types live beside the table of keys, which names them in the reference
from cosim.scene.keytable import STRUCTURE_TYPES, SUBSYSTEM_TYPES

log = logging.getLogger(__name__)

__all__ = ["Scene", "SchemeSpec", "MultibodySpec", "BodySpec", "JointSpec", "RigidSpec",
           "FMUSpec", "StructureSpec", "ContactSpec", "resolve_scheme", "STRUCTURE_TYPES",
           "SUBSYSTEM_TYPES"]



class _ByKey:
    """Read a field by key too: ``spec["law"]`` is ``spec.law``."""

    def __getitem__(self, key: str):
        try:
            return getattr(self, key)
        except AttributeError:
            raise KeyError(key) from None

    def get(self, key: str, default=None):
        """``spec.key`` if the spec has that field, else ``default``."""
        return getattr(self, key, default)


@dataclass(frozen=True)
class BodySpec(_ByKey):
    """A rigid body of a multibody side.

    Attributes
    ----------
    name : str
    mass : float
        [kg]
    inertia : float
        About the centre of mass [kg m^2].
    com : tuple of float
        Centre of mass in the body frame [m].
    points : dict
        Point name -> (x, y) in the body frame [m].
    key : str
        Its key path in the file, for messages.
    """

    name: str
    mass: float
    inertia: float
    com: tuple
    points: dict
    key: str


@dataclass(frozen=True)
class JointSpec(_ByKey):
    """The joint of a body to its parent.

    Attributes
    ----------
    name : str
    kind : str
        ``revolute`` or ``prismatic``.
    parent : int
        Index of the parent body, -1 for the ground.
    offset : tuple of float
        Joint place in the parent's frame [m].
    axis : tuple of float
        Unit sliding direction of a prismatic joint.
    angle : float
        Fixed rotation of the body frame [rad].
    q0, dq0 : float
        Initial coordinate [m or rad] and velocity [m/s or rad/s].
    effects : tuple
        Its springs, dampers and drives (:mod:`multibody.effects` objects).
    """

    name: str
    kind: str
    parent: int
    offset: tuple
    axis: tuple
    angle: float
    q0: float
    dq0: float
    effects: tuple = ()


@dataclass(frozen=True)
class MultibodySpec(_ByKey):
    """A multibody side: a tree of bodies in joint coordinates.

    Attributes
    ----------
    name, key : str
    bodies : tuple of BodySpec
    joints : tuple of JointSpec
        One per body, parents first.
    ports : dict
        Point name -> (body index, (x, y) in the body frame [m]).
    integrator : str
        Name in :data:`cosim.core.ode.INTEGRATORS`.
    max_step : float or None
        Its (largest) step [s]; None: ``rk4`` takes the scheme's
        :attr:`SchemeSpec.default_step`, adaptive methods choose.
    integrator_options : dict
        ``rtol``, ``atol`` (adaptive) or ``free_step`` [s] (``rk4``).
    """

    type: ClassVar[str] = "multibody"
    name: str
    key: str
    bodies: tuple
    joints: tuple
    ports: dict
    integrator: str = "rk4"
    max_step: float | None = None
    integrator_options: dict = field(default_factory=dict)


@dataclass(frozen=True)
class RigidSpec(_ByKey):
    """A fixed side: named points in the world frame.

    Attributes
    ----------
    name, key : str
    points : dict
        Point name -> (x, y) [m].
    """

    type: ClassVar[str] = "rigid"
    name: str
    key: str
    points: dict


@dataclass(frozen=True)
class FMUSpec(_ByKey):
    """A co-simulation Functional Mock-up Unit (:mod:`cosim.scene.fmu`).

    Attributes
    ----------
    name, key : str
    path : str
        The ``.fmu`` file, resolved against the scene file's folder.
    ports : dict
        Port name -> :class:`cosim.sides.fmu.FMUPort` (its variables and
        port mass [kg] or the output variable that reports it).
    parameters : dict
        Parameter variable -> start value.
    coordinates : dict
        Name -> (position, velocity) output variables.
    energy : str or None
        Output variable of its mechanical energy [J].
    fmi_version : str
    can_get_set_state : bool
        Whether the FMU saves and restores its state (rollback).
    """

    type: ClassVar[str] = "fmu"
    name: str
    key: str
    path: str
    ports: dict
    parameters: dict
    coordinates: dict
    energy: str | None
    fmi_version: str
    can_get_set_state: bool


@dataclass(frozen=True)
class StructureSpec(_ByKey):
    """A linear structure: its model (not yet assembled), ports, kept modes,
    integrator and initial state.

    Attributes
    ----------
    name, key : str
    type : str
        ``chain``, ``beam``, ``cable``, ``string`` or ``rod``.
    model
        The :mod:`fem` model (``Chain``, ``Beam``, ``String``, ``Rod``).
    ports : dict
        Point name -> material coordinate [m] (a mass index for a chain).
    n_modes : int or None
        Modes kept (``modes.count``).
    cutoff_hz : float or None
        Highest kept frequency [Hz] (``modes.cutoff_hz``).
    contact_step : float
        RK4 step while a hosted contact is closed [s].
    integrator : str
        Name in :data:`fem.STRUCTURAL_INTEGRATORS`.
    integrator_options : dict
        ``beta``, ``gamma``, ``alpha`` or ``rho_inf`` as given.
    initial_velocity : float or tuple of float
        Uniform initial velocity along the structure's direction [m/s] (a
        plane body's: a world 2-vector).
    static_equilibrium : bool
        Start at the static state under gravity and ``static_loads``.
    static_loads : dict
        Point name -> force along the direction [N].
    static_correction : bool
        A plane body's contacts get the dropped modes' static compliance in
        series with their spring.
    modal_cache : str or None
        The folder where a plane body's modes are kept between runs.
    """

    name: str
    key: str
    type: str
    model: object
    ports: dict
    n_modes: int | None = None
    cutoff_hz: float | None = None
    contact_step: float = DEFAULT_CONTACT_STEP
    integrator: str = "exact"
    integrator_options: dict = field(default_factory=dict)
    initial_velocity: float | tuple = 0.0
    static_equilibrium: bool = False
    static_loads: dict = field(default_factory=dict)
    static_correction: bool = False
    modal_cache: str | None = None

    @property
    def modes(self) -> dict:
        """``{"n_modes": ..., "cutoff_hz": ...}``, the keywords of :func:`fem.modes`."""
        return {"n_modes": self.n_modes, "cutoff_hz": self.cutoff_hz}


@dataclass(frozen=True)
class ContactSpec(_ByKey):
    """A contact between a point of side a and a point of side b.

    Attributes
    ----------
    name, key : str
    a, b : tuple of str
        ``(subsystem, point)`` of each side.
    normal : tuple of float
        Unit normal from b towards a.
    offset : float
        Gap added along the normal [m].
    law
        The :mod:`couplers` contact law.
    placement : str
        ``embedded`` (one side's integrator evaluates it) or ``coupler``.
    host : str or None
        The side that integrates an embedded contact between two moving
        sides, when the scene names it.
    follow : bool
        Side b's point follows side a's along a line structure or a plane
        body's boundary.
    connection : couplers.Connection or None
        Its grasp and friction, if any.
    radius : float or None
        A circle's radius [m] (side a's point its centre, side b a plane
        body), or None for a point contact.
    """

    name: str
    key: str
    a: tuple
    b: tuple
    normal: tuple
    law: object
    offset: float = 0.0
    placement: str = "coupler"
    host: str | None = None
    follow: bool = False
    connection: object = None
    radius: float | None = None


@dataclass(frozen=True)
class SchemeSpec:
    """The coupling scheme a run uses, resolved by :func:`~cosim.scene.specs.resolve_scheme`.

    Attributes
    ----------
    name : str
        Name in :data:`cosim.core.schemes.COUPLING_SCHEMES`.
    options : dict
        The options it takes, validated (``macro_step`` [s], ...).
    default_step : float
        The ``rk4`` step of a multibody side that gives no ``max_step`` [s]:
        the macro step when shorter than
        :data:`~cosim.scene.keys.DEFAULT_MULTIBODY_STEP`, else that.
    """

    name: str
    options: dict
    default_step: float

    @property
    def macro_step(self) -> float | None:
        """[s], or None for a scheme without one (monolithic)."""
        return self.options.get("macro_step")


def resolve_scheme(name: str, options: dict, tables: dict, *, file, t_end: float,
                   stacklevel: int = 2, subsystems=(), contacts=(),
                   max_steps: float = MAX_STEPS, chosen: bool = False) -> SchemeSpec:
    """Choose the scheme ``name`` and the options it runs with.

    The one place that drops the options the scheme ignores (with one
    warning naming them, when the scene chose the scheme; when the caller
    chose another, ``chosen``, the scene's options for the schemes it did
    not choose are no fault of the scene: one line at the log's info level
    says what was left out), merges the ``[scheme.NAME]`` table of that scheme,
    requires a macro step of the schemes that take one and bounds the work
    of a run (:func:`cosim.scene.work.estimate_work`: macro steps, their
    iterations and the steps of each side in them).

    Parameters
    ----------
    name : str
        The scheme.
    options : dict
        Options given in ``[scheme]``, each already checked against the
        scheme that takes it.
    tables : dict
        Scheme name -> its ``[scheme.NAME]`` options, checked.
    file : path-like
        The scene file, for messages.
    t_end : float
        End time [s].
    stacklevel : int
        Of the warning, counted from the caller of this function.
    subsystems, contacts : sequence of specs
        The scene's, whose steps the work counts.
    max_steps : float
        Most integrator steps a run may take (the scene's ``guard.max_steps``).
    chosen : bool
        Whether the caller chose the scheme (``--scheme``, ``scheme=``) rather
        than the scene.

    Returns
    -------
    SchemeSpec

    Raises
    ------
    SceneError
        If the scheme is unknown, needs a macro step that is missing, or the
        run would take more than ``max_steps`` steps
        (:func:`cosim.scene.work.check_work`).
    """
    from cosim.scene.work import check_work, estimate_work
    from cosim.core.schemes import get_scheme
    try:
        cls = get_scheme(name)
    except ValueError as exc:
        raise SceneError(file, "scheme.name", str(exc)) from None
    ignored = sorted(k for k in options if k not in cls.options)
    if ignored and chosen:
        log.info("%s: scheme `%s` runs without the scene's options %s (for other schemes)",
                 file, name, ignored)
    elif ignored:
        warnings.warn(f"{file}: scheme `{name}` ignores the options {ignored}",
                      stacklevel=stacklevel + 1)
    opts = {k: v for k, v in options.items() if k in cls.options}
    opts.update(tables.get(name, {}))
    if "macro_step" in cls.options and "macro_step" not in opts:
        raise SceneError(file, "scheme.macro_step", f"is required by scheme `{name}` [s]")
    H = opts.get("macro_step")
    spec = SchemeSpec(name, opts, min(H or DEFAULT_MULTIBODY_STEP, DEFAULT_MULTIBODY_STEP))
    check_work(file, estimate_work(spec, t_end, subsystems, contacts), max_steps)
    return spec


@dataclass(frozen=True)
class Scene:
    """A validated scene, ready to :meth:`~cosim.Scene.build`.

    Attributes
    ----------
    name, path, variant : str
    t_end : float
        End time [s].
    scheme : str
        Default coupling scheme's name.
    scheme_options : dict
        Options of that scheme, validated.
    output_every : int
        Record every n-th accepted step.
    subsystems : tuple
        :class:`~cosim.scene.specs.MultibodySpec`, :class:`~cosim.scene.specs.RigidSpec` and
        :class:`~cosim.scene.specs.StructureSpec`, in the file's order.
    contacts : tuple of ContactSpec
    gravity : tuple of float or None
        [m/s^2]
    data : dict
        The merged scene table (after variant and overrides).
    export : tuple of str
        Structures whose fields are written (``output.export``).
    export_every : int
    estimate : bool
        Whether ``cosim run`` estimates the run's error (``output.estimate``,
        :func:`cosim.studies.estimate.estimate_errors`).
    scheme_tables : dict
        Scheme name -> options that apply only when that scheme runs
        (``[scheme.NAME]`` tables, e.g. the monolithic reference's tolerances
        in a scene whose default is a co-simulation), validated.
    guard : GuardOptions
        The run guard's settings (``[guard]``: ``energy_growth``,
        ``energy_check``, ``energy_floor``, ``chatter_switches``,
        ``chatter_window``), see :mod:`cosim.core.guard`.
    max_steps : float
        Most integrator steps a run may take (``guard.max_steps``), see
        :mod:`cosim.scene.work`.
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
    max_steps: float = MAX_STEPS
    estimate: bool = True

    def scheme_spec(self, scheme: str | None = None) -> SchemeSpec:
        """The scheme a run uses: the scene's, or ``scheme`` with the scene's
        options that it takes (see :func:`~cosim.scene.specs.resolve_scheme`)."""
        return resolve_scheme(scheme or self.scheme, self.scheme_options, self.scheme_tables,
                              file=self.path, t_end=self.t_end, stacklevel=3,
                              subsystems=self.subsystems, contacts=self.contacts,
                              max_steps=self.max_steps,
                              chosen=scheme is not None and scheme != self.scheme)

    def work(self, scheme: str | None = None, system=None):
        """The work a run of ``scheme`` (the scene's by default) will do,
        counted before it starts (:func:`cosim.scene.work.estimate_work`;
        ``system``, the built one, lets the monolithic scheme's count see
        the stiffest mode)."""
        from cosim.scene.work import estimate_work
        with warnings.catch_warnings():     # the options it ignores: said when it was read
            warnings.simplefilter("ignore")
            spec = self.scheme_spec(scheme)
        return estimate_work(spec, self.t_end, self.subsystems, self.contacts, system)

    def build(self, scheme: str | None = None, *, run_fmu: bool = True):
        """Make the coupled system and the scheme (optionally another one);
        ``run_fmu=False`` builds FMU sides from their model descriptions
        alone, running nothing of them.

        See :func:`cosim.scene.build.build_system`.  The work of the run is
        counted again with the system (:meth:`work`): the monolithic
        solver's steps depend on its stiffest mode, known only now (a
        co-simulation's count was checked when its scheme was resolved,
        before anything was assembled).

        Raises
        ------
        SceneError
            As :func:`~cosim.scene.build.build_system`, and if the run would
            take more steps than ``guard.max_steps``.
        """
        from cosim.scene.build import build_system
        from cosim.scene.work import check_work
        system, sch = build_system(self, scheme, run_fmu=run_fmu)
        check_work(self.path, self.work(scheme, system), self.max_steps)
        return system, sch
