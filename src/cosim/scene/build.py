"""From a validated scene to a coupled system and a scheme.

The builder reads the typed specs of a :class:`~cosim.scene.specs.Scene`
(:mod:`cosim.scene.specs`) and nothing of the file; it imports neither the
loader nor the specs' module (the scene's :meth:`~cosim.scene.specs.Scene.build`
calls it, and resolves the scheme through :func:`~cosim.scene.specs.resolve_scheme`).
"""
from __future__ import annotations

import copy
import math
from collections import OrderedDict

import numpy as np

from couplers import PointContact
import multibody                     # its joint effects load where a scene has some
from multibody import Body, Joint, TreeModel

from cosim.sides.multibody import MultibodySubsystem
from cosim.core.ode import get_integrator
from cosim.core.preflight import stiffest_normal
from cosim.errors import PluginError
from cosim.scene.checks import SceneError
from cosim.core.schemes import get_scheme
from cosim.core.subsystem import RigidReference
from cosim.core.system import ContactLink, CoupledSystem

__all__ = ["build_system", "build_side", "embedded_step_limit", "clear_assembled", "ASSEMBLED_KEPT"]

#: RK4's stability limit on an undamped oscillator is omega*dt = 2*sqrt(2).
_RK4_LIMIT = 2.0 * math.sqrt(2.0)


def _multibody(spec, scene, default_step):
    """A :class:`MultibodySubsystem` of a ``MultibodySpec``."""
    try:
        bodies = [Body(b.name, b.mass, b.inertia, b.com, b.points) for b in spec.bodies]
        joints = [Joint(j.name, j.kind, j.parent, j.offset, j.axis, j.angle)
                  for j in spec.joints]
        model = TreeModel(bodies, joints)
        cls = get_integrator(spec.integrator)
        if spec.integrator == "rk4":
            integ = cls(max_step=spec.max_step or default_step, **spec.integrator_options)
        else:
            step = {"max_step": spec.max_step} if spec.max_step else {}
            integ = cls(**step, **spec.integrator_options)
    except ValueError as exc:
        raise SceneError(scene.path, spec.key, str(exc)) from None
    q0 = [j.q0 for j in spec.joints]
    dq0 = [j.dq0 for j in spec.joints]
    effects = [e for j in spec.joints for e in j.effects]
    _check_mass_matrix(model, q0, spec, scene)
    return MultibodySubsystem(spec.name, model, q0, dq0, spec.ports, scene.gravity, integ,
                              multibody.JointEffects(model.n_dof, effects) if effects else None)


def _check_mass_matrix(model, q0, spec, scene) -> None:
    """Refuse a tree whose mass matrix at its initial pose is singular (or
    not finite): some joint would move no mass, and no integrator can step it."""
    M = model.mass_matrix(np.asarray(q0, float))
    ok = bool(np.all(np.isfinite(M)))
    if ok:
        try:
            np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            ok = False
    if not ok:
        scale = float(np.max(np.abs(np.diag(M)))) if np.all(np.isfinite(M)) else math.inf
        raise SceneError(scene.path, f"{spec.key}.bodies",
                         f"must give a mass matrix that is regular at the initial joint "
                         f"coordinates, got a singular one (largest diagonal entry {scale:.3g}): "
                         f"some joint moves no mass (a massless body at a branch's end, or "
                         f"prismatic joints along one axis); give the bodies mass and inertia, "
                         f"or change the joints' axes")


def _assembled(model):
    """``model.assemble()``, a plug-in structure's checked to be a
    :class:`fem.LinearStructure` (:class:`~cosim.errors.PluginError` else;
    what it raises is blamed on it by :func:`cosim.core.plugin_guard.blame`,
    its ValueError aside, which names a key of the scene)."""
    structure = model.assemble()
    if type(model).__module__.split(".")[0] != "fem":        # a plug-in's? its return checked
        import fem

        from cosim.core.plugin_guard import origin_of, refuse
        if origin_of(model) is not None and not isinstance(structure, fem.LinearStructure):
            raise refuse(model, "assemble()", structure, "a fem.LinearStructure")
    return structure


#: how many assembled structures (and their modes) a process keeps: a run on
#: request builds its scene for the choice, the run, its companions and a
#: refinement, and a sweep once per point, each time the same structure, and
#: the assembly is most of a build once the modes are remembered
#: (:data:`fem.modal._SOLVED`); each build gets copies of its own
ASSEMBLED_KEPT = 4

#: (model, modes) -> (structure, basis) of the latest assemblies
_ASSEMBLED: "OrderedDict" = OrderedDict()


def _assembly_key(spec):
    """The key an assembled structure is kept under: its model (a frozen
    value of :mod:`fem`: equal models assemble equal structures) and the
    modes asked; None where it is not kept (a plug-in's model, which may
    assemble anything; a plane body, whose assembly the build changes, or
    whose modes are cached on disk)."""
    model = spec.model
    if (type(model).__module__.split(".")[0] != "fem" or spec.type == "plane"
            or getattr(spec, "modal_cache", None)):
        return None
    try:
        key = (type(model), model, tuple(sorted(spec.modes.items())))
        hash(key)
    except TypeError:                   # a model with a list or an array in it
        return None
    return key


def clear_assembled() -> None:
    """Forget the assembled structures kept (:data:`ASSEMBLED_KEPT`): the
    next build assembles again, as a new process would."""
    _ASSEMBLED.clear()


def _structure(spec, scene, macro_step):
    """Assemble a structure, keep its modes, set its initial state."""
    import fem

    from cosim.sides.fem import StructureSubsystem
    try:
        key = _assembly_key(spec)
        if key is not None and key in _ASSEMBLED:
            structure, basis = copy.deepcopy(_ASSEMBLED[key])   # each build its own arrays
            _ASSEMBLED.move_to_end(key)
        else:
            structure = _assembled(spec.model)
            if spec.type == "plane":       # its ports move along their segments' normal
                from cosim.scene.plane_build import port_direction
                port_direction(structure, spec.ports, scene.path, spec.key)
            if getattr(spec, "modal_cache", None):     # a plane body's, kept on disk
                from cosim.scene.plane_build import cached_basis
                basis = cached_basis(structure, spec, scene.path)
            else:
                basis = fem.modes(structure, **{k: v for k, v in spec.modes.items() if v})
            if key is not None:
                _ASSEMBLED[key] = copy.deepcopy((structure, basis))
                while len(_ASSEMBLED) > ASSEMBLED_KEPT:
                    _ASSEMBLED.popitem(last=False)
    except PluginError:                 # a plug-in's assemble() returned what is no structure
        raise
    except ValueError as exc:
        msg = _unit_slip_first(str(exc), spec, scene)
        for arg, key in (("cutoff_hz", "cutoff_hz"), ("n_modes", "count")):
            if msg.startswith(f"`{arg}` "):     # the modes table's key, not the function's
                raise SceneError(scene.path, f"{spec.key}.modes.{key}",
                                 msg[len(arg) + 3:]) from None
        raise SceneError(scene.path, spec.key, msg) from None
    except ImportError as exc:        # scikit-fem is an optional extra
        raise SceneError(scene.path, f"{spec.key}.type",
                         f"`{spec.type}` needs {exc.name or 'a missing package'}, which is "
                         f"not installed: pip install \"cosim[fem]\"") from None
    n = structure.n_dof
    u0 = None
    if spec.static_equilibrium:
        loads = spec.static_loads
        if scene.gravity is None and not loads:
            raise SceneError(scene.path, f"{spec.key}.static_equilibrium",
                             "needs gravity (`effects.gravity`) or `static_loads` to have a "
                             "meaning")
        f = (structure.gravity_load(np.asarray(scene.gravity)) if scene.gravity is not None
             else np.zeros(structure.n_dof))
        # what the connections closed at the start carry: the structure starts
        # at rest under them, so a grasp at t = 0 does not set it ringing
        for port, force in loads.items():
            f = f + structure.point_load(spec.ports[port], force)
        try:
            u0 = structure.static_displacement(f)
        except ValueError as exc:         # a structure free to move, or too weakly held
            raise SceneError(scene.path, f"{spec.key}.static_equilibrium",
                             f"cannot be met: {exc}") from None
    if spec.type == "plane":          # a uniform velocity vector
        v0 = structure.translation(spec.initial_velocity) if any(spec.initial_velocity) else None
    else:
        v0 = np.full(n, spec.initial_velocity) if spec.initial_velocity else None
    try:
        cls = StructureSubsystem
        if spec.type == "plane":      # records its modes, never the whole field
            from cosim.sides.plane import PlaneSubsystem as cls
        sub = cls(spec.name, structure, basis, spec.ports, u0, v0, scene.gravity,
                  spec.contact_step, spec.integrator, spec.integrator_options)
    except (TypeError, ValueError) as exc:
        raise SceneError(scene.path, f"{spec.key}.integrator", str(exc)) from None
    H = macro_step
    if H is not None and H > sub.max_stable_step():
        stable = sub.max_stable_step()
        advised = _printed_below(stable, lambda h: not h > stable)
        raise SceneError(scene.path, f"{spec.key}.integrator.method",
                         f"`{spec.integrator}` is stable only for steps below "
                         f"{stable:.3g} s (highest kept mode "
                         f"{basis.frequencies_hz[-1]:.4g} Hz), the macro step is {H:.3g} s; "
                         f"keep fewer modes (a lower `modes.cutoff_hz`), set "
                         f"`scheme.macro_step` to {advised:.2g} s or less, or use `exact`")
    return sub


def _printed_below(limit: float, ok) -> float:
    """``limit`` [s] rounded down to the two digits a message prints, lowered
    by a tenth while ``ok`` (the refusal's own test) finds it too large: the
    value a refusal advises passes it as printed."""
    h = limit
    for _ in range(40):
        if not (h > 0 and math.isfinite(h)):
            break
        e = math.floor(math.log10(h)) - 1
        h = float(f"{math.floor(h / 10.0 ** e) * 10.0 ** e:.2g}")
        if ok(h):
            return h
        h *= 0.9
    return limit


def _unit_slip_first(msg: str, spec, scene) -> str:
    """``msg`` of :func:`fem.modes`, whose advice to raise ``modes.cutoff_hz``
    is put after the unit slip that more likely made every mode too high: a
    section larger than the structure (millimetres read as metres: about
    1e6 times too stiff for its mass, :func:`cosim.scene.plausible.section_problem`),
    or a lowest natural frequency above :data:`~cosim.scene.plausible.HIGH_HZ`."""
    import re

    from cosim.scene.plausible import HIGH_HZ, section_problem
    advice = "; give a cutoff above it"
    if not (msg.startswith("`cutoff_hz` keeps no mode") and msg.endswith(advice)):
        return msg
    problem = section_problem(scene, spec)
    if problem is not None:
        why = problem["message"]
    else:
        m = re.search(r"lowest natural frequency is ([0-9.eE+-]+) Hz", msg)
        if m is None or not float(m.group(1)) > HIGH_HZ:
            return msg
        why = (f"a lowest natural frequency above {HIGH_HZ:g} Hz is no structure's as meant: "
               f"check the units of `{spec.key}`'s density, stiffness and section")
    return (msg[:-len(advice)] + f". Check the units first: {why}. A higher cutoff would run "
            f"the {spec.type} as written; if its numbers are right, give a cutoff above it")


def build_side(side, scene, default_step: float, macro_step: float | None = None):
    """The subsystem of a rigid, multibody or structure spec ``side`` of
    ``scene``: none of them runs code the scene names (an FMU side, which
    does, is built by :func:`cosim.scene.fmu_build.build_fmu` only).

    Parameters
    ----------
    default_step : float
        The fixed step of an ``rk4`` tree that gives no ``max_step`` [s].
    macro_step : float, optional
        The scheme's macro step [s], against which a structure's integrator
        is checked (not checked when None).

    Raises
    ------
    SceneError
        If a model cannot be built.
    """
    if side.type == "rigid":
        return RigidReference(side.name, side.points)
    if side.type == "multibody":
        return _multibody(side, scene, default_step)
    if side.type == "fmu":
        raise ValueError(f"subsystem `{side.name}` is an FMU: build_fmu builds it")
    return _structure(side, scene, macro_step)


def embedded_step_limit(system, c: int):
    """The largest RK4 step the build accepts for the side that integrates
    embedded contact ``c`` of ``system`` (half RK4's stability limit,
    ``sqrt(2) / omega``, with ``omega`` the contact's frequency against that
    side's port mobility and, for a structure, its highest kept mode, which
    the same RK4 steps while the contact is closed): ``(limit, the side's
    step, its key, omega)``, or None where no RK4 step integrates ``c`` (a
    coupler contact, a rigid law, a circle, another integrator).  ``cosim info``
    prints this limit, so the step it prints is one the build accepts."""
    ln = system.links[c]
    if ln.placement != "embedded" or ln.contact.law.rigid or c in system.circles:
        return None
    subs = system.subsystems
    s = system.embedded[c][0]
    port = ln.port_a if s == ln.sub_a else ln.port_b
    mob = subs[s].port_mobility(port, ln.contact.normal)
    omega = math.sqrt(stiffest_normal(ln)[0] * mob)
    if isinstance(subs[s], MultibodySubsystem):
        if subs[s].integrator.name != "rk4":
            return None
        dt, key = subs[s].integrator.max_step, "max_step"
    else:   # a structure: RK4 while the contact is closed, over every kept mode
        dt = subs[s].closed_contact_step()
        if dt is None:
            return None
        omega = max(omega, float(np.max(subs[s].omega)))
        key = "contact_step"
    return 0.5 * _RK4_LIMIT / omega, dt, key, omega


def build_system(scene, scheme: str | None = None, *, run_fmu: bool = True):
    """Build the subsystems, contacts and the coupling scheme of ``scene``.

    Parameters
    ----------
    scene : Scene
        A validated scene (:class:`cosim.scene.specs.Scene`).
    scheme : str, optional
        Another scheme than the scene's; the scene resolves it
        (:meth:`~cosim.scene.specs.Scene.scheme_spec`).
    run_fmu : bool
        Whether FMU sides are instantiated (their code runs); if not, each
        is built from its model description alone
        (:class:`~cosim.sides.fmu_description.DescribedFMU`), which
        describes but cannot step.

    Raises
    ------
    SceneError
        If a model cannot be built, or an embedded contact is too stiff for
        the integrator step of the side that carries it.
    """
    spec = scene.scheme_spec(scheme)
    name, opts = spec.name, spec.options
    if scene.export:
        import importlib.util
        if importlib.util.find_spec("meshio") is None:
            raise SceneError(scene.path, "output.export",
                             'needs meshio, which is not installed: pip install "cosim[fem]", '
                             'or drop `output.export`')
    cls = get_scheme(name)
    subs = []
    for side in scene.subsystems:
        if side.type == "fmu":            # a Functional Mock-up Unit: cosim.scene.fmu
            from cosim.scene.fmu_build import build_fmu
            subs.append(build_fmu(side, scene, name, opts, run=run_fmu))
        else:
            subs.append(build_side(side, scene, spec.default_step, spec.macro_step))
    names = [s.name for s in subs]
    types = {side.name: side.type for side in scene.subsystems}
    links = []
    for c in scene.contacts:
        sa, sb = names.index(c.a[0]), names.index(c.b[0])
        pa, pb = subs[sa].port_index(c.a[1]), subs[sb].port_index(c.b[1])
        law = c.law
        if "plane" in (types[c.a[0]], types[c.b[0]]) and c.radius is None:   # static
            # correction, pre-flight rules (of a point contact)
            from cosim.scene.plane_build import corrected_law
            law = corrected_law(c, scene, subs, ((sa, pa), (sb, pb)), name)
        contact = PointContact(c.name, law, c.normal, c.offset)
        # the monolithic ODE evaluates every penalty law itself; a rigid law
        # stays with its moving side, which resolves the impact
        placement = ("coupler" if name == "monolithic" and not c.law.rigid
                     else c.placement)
        host = None
        if placement == "embedded" and not (subs[sa].rigid or subs[sb].rigid):
            if c.host is not None:
                host = names.index(c.host)
            elif c.follow:  # b's structure: it alone applies the slope force of its surface
                host = sb
            else:   # the lighter side: it resolves the spring, the heavier one lags least
                mob_a = subs[sa].port_mobility(pa, contact.normal)
                mob_b = subs[sb].port_mobility(pb, contact.normal)
                host = sa if mob_a >= mob_b else sb
        if c.radius is not None:        # a circle: the plane body b hosts it
            host = sb
            subs[sb].add_circle(c.name, c.radius, law.contact_stiffness)
        links.append(ContactLink(contact, sa, pa, sb, pb, placement, c.follow, host,
                                 c.connection))
    if any(side.type == "fmu" for side in scene.subsystems):
        from cosim.scene.fmu_build import settle_fmu_contacts
        links = settle_fmu_contacts(scene, subs, links)
    system = CoupledSystem(subs, links)
    for c in scene.contacts:
        if c.radius is not None:
            from cosim.scene.circle_rules import circle_build_rules
            seq = [n for n in (opts.get("sequence") or names) if n in names]
            circle_build_rules(scene, name, system, c,
                               [n for n in seq if not subs[names.index(n)].rigid])
    for c, ln in enumerate(links):
        found = embedded_step_limit(system, c)
        if found is None:
            continue
        limit, dt, key, omega = found
        s = system.embedded[c][0]
        if dt > limit:
            advised = _printed_below(limit, lambda h, w=omega: not w * h > 0.5 * _RK4_LIMIT)
            raise SceneError(scene.path, f"subsystems.{subs[s].name}.integrator.{key}",
                             f"is {dt:.3g} s, too large for contact `{ln.contact.name}` "
                             f"(omega = {omega:.4g} rad/s): the integrator needs a step below "
                             f"{limit:.3g} s to resolve it; set it to {advised:.2g} s or less")
    seq = opts.get("sequence")
    if seq is not None:
        moving = [s.name for s in subs if not s.rigid]
        unknown = [n for n in seq if n not in names]
        if unknown or sorted(n for n in seq if n in moving) != sorted(moving):
            raise SceneError(scene.path, "scheme.sequence",
                             f"must list every moving subsystem once ({moving}), got {seq!r}")
    sub_steps = opts.get("substeps") or {}
    moving = [s.name for s in subs if not s.rigid]
    for sname, m in sub_steps.items():
        if sname not in moving:
            raise SceneError(scene.path, f"scheme.substeps.{sname}",
                             f"names no moving subsystem; moving subsystems are {moving}")
        hosts = [system.links[c].contact.name for c, hc in system.hosted.items()
                 if subs[hc.host].name == sname]
        if m > 1 and hosts:
            raise SceneError(scene.path, f"scheme.substeps.{sname}",
                             f"`{sname}` hosts contacts {hosts}, which its integrator "
                             f"resolves continuously; sub-steps would only cut its step, so "
                             f"give it 1 (got {m}) or a smaller integrator step")
    try:
        sch = cls(**opts)
    except (TypeError, ValueError) as exc:
        raise SceneError(scene.path, "scheme", str(exc)) from None
    return system, sch
