"""Optional faces of a side are declared (``Subsystem.capabilities``), not
probed for: a declaration names only known faces and cannot promise a
member the class lacks, every shipped side declares what it has, and the
code that uses a face asks the declaration."""
import ast
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.core.subsystem import CAPABILITIES, RigidReference, Subsystem

SRC = Path(cosim.__file__).parent


class _Still(Subsystem):
    def _step_impl(self, t, h, inputs):
        pass

    def derivatives(self, t, x, u):
        return np.zeros(0)

    def outputs(self, t, x):
        return np.zeros((1, 2)), np.zeros((1, 2))

    def energy(self, x=None):
        return 0.0


def test_a_side_without_declarations_has_none_and_neutral_faces():
    side = _Still("s", ["p"])
    assert side.capabilities == frozenset()
    assert side.host_cpu_time == 0.0
    assert side.closed_form_contacts is False
    assert side.unknown_port_mass(0) is None
    assert side.closed_contact_step() is None


def test_an_unknown_capability_is_refused_when_the_class_is_made():
    with pytest.raises(TypeError, match="unknown capabilities \\['teleport'\\]"):
        type("Bad", (_Still,), {"capabilities": frozenset({"teleport"})})


def test_a_capability_without_its_members_is_refused_when_the_class_is_made():
    with pytest.raises(TypeError, match="has no \\['move_port', 'material_coordinate', "
                                        "'surface_tangent'\\]"):
        type("Bad", (_Still,), {"capabilities": frozenset({"moving_ports"})})


def _sides():
    from cosim.sides.fem import StructureSubsystem
    from cosim.sides.fmu import FMUSubsystem
    from cosim.sides.fmu_description import DescribedFMU
    from cosim.sides.multibody import MultibodySubsystem
    return {MultibodySubsystem: {"rigid_impacts", "impact_watch", "connections",
                                                  "skeleton", "sampled_steps", "compiled_loop"},
            StructureSubsystem: {"rigid_impacts", "moving_ports", "modes", "compiled_loop",
                                 "compiled_follow"},
            FMUSubsystem: {"fmi"}, DescribedFMU: {"fmi"}, RigidReference: {"compiled_loop"}}


def test_each_shipped_side_declares_its_faces():
    for cls, faces in _sides().items():
        assert cls.capabilities == faces, cls.__name__
        for face in faces:
            assert all(hasattr(cls, m) for m in CAPABILITIES[face])


def test_a_built_scene_sides_have_the_members_their_faces_promise():
    system, _ = cosim.load_scene("cases/beam_impact.toml").build()
    for sub in system.subsystems:
        if "rigid_impacts" in sub.capabilities:
            assert isinstance(sub.impact_log, list)
        assert ("impact_watch" in sub.capabilities) == hasattr(sub, "impact_watch")
        if "modes" in sub.capabilities:
            assert np.size(sub.omega) and sub.structure is not None and sub.basis is not None
        if "skeleton" in sub.capabilities:
            assert sub.model is not None


#: members of a side that were probed for before they were declared
_FACE_MEMBERS = {m for ms in CAPABILITIES.values() for m in ms} | {
    "impact_log", "impact_watch", "omega", "model_description", "structure", "host_cpu_time",
    "unknown_port_mass", "_closed_form", "preflight", "rigid"}


@pytest.mark.parametrize("package", ["core", "scene", "plot"])
def test_no_code_probes_a_side_or_scheme_for_a_face(package):
    probes = []
    for path in sorted((SRC / package).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id in ("hasattr", "getattr") and len(node.args) >= 2
                    and isinstance(node.args[1], ast.Constant)
                    and node.args[1].value in _FACE_MEMBERS):
                probes.append(f"{path.relative_to(SRC)}:{node.lineno} "
                              f"{node.func.id}(..., {node.args[1].value!r})")
    assert not probes, "\n".join(probes)


def test_the_compiled_loop_face_of_a_built_scene_sides():
    """The face the compiled loop steps a side through (``compiled_loop``,
    cosim.core.loop_face) hands the side's own live state: its embedded
    contacts, its kernel where the kernel steps it, a structure's record of
    closed ends (one per hosted contact) and none for a multibody side."""
    from cosim.sides.fem import StructureSubsystem
    from cosim.sides.multibody import MultibodySubsystem
    system, _ = cosim.load_scene("cases/beam_impact.toml").build()
    kinds = set()
    for sub in system.subsystems:
        assert "compiled_loop" in sub.capabilities
        kinds.add(type(sub))
        kernel = sub.compiled_step(None)         # built on the first ask
        assert (kernel is not None) == (getattr(sub, "kernel", None) == "compiled")
        if isinstance(sub, StructureSubsystem):
            assert sub.closed_end.dtype == np.int8
            assert sub.closed_end.shape == (len(sub.embedded_contacts),)
            assert sub.switch_handler is not None
        elif isinstance(sub, MultibodySubsystem):
            assert sub.closed_end is None and sub.switch_handler is not None
        else:
            assert sub.rigid and sub.closed_end is None and sub.compiled_step(None) is None
            assert tuple(sub.embedded_contacts) == ()
    assert {StructureSubsystem, MultibodySubsystem} <= kinds
    hosts = [sub for sub in system.subsystems if len(sub.embedded_contacts)]
    assert len(hosts) == 2                      # the beam's and the arm's
    for sub in hosts:
        assert sub.embedded_contacts is sub.embedded_contacts   # the live list, not a copy
