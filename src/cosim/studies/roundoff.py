"""Copies of a scene whose initial state is moved by a few ulps.

A train of impacts amplifies round-off: two machines whose numpy differs by
one ulp in an array power (a CPU with AVX-512 against one without), or two
builds of the same kernel, can end a loose run with another contact count.
A result that a user may believe must therefore hold for the scene *and* for
copies of it that differ only by round-off in the initial state; a result
that changes among the copies is a distribution, not a number.

:func:`perturbed` moves every nonzero initial value of a scene (joint
coordinates ``q0`` and velocities ``dq0`` of a multibody, a structure's
``initial_velocity``) by the same signed number of ulps; :func:`spread`
returns the scene and ``copies - 1`` such copies, with offsets
:data:`OFFSETS` (+1, -1, +2, -2, ... ulps).  The tests of discrete outcomes
(``tests/roundoff.py``) and ``cosim bench --spread`` use these.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

__all__ = ["OFFSETS", "nudge", "perturbed", "perturbed_overrides", "spread", "state_keys"]

#: the ulp offsets of the copies after the unmoved scene, in order
OFFSETS = (1, -1, 2, -2, 3, -3, 4, -4, 6, -6, 8, -8)


def nudge(x: float, ulps: int) -> float:
    """``x`` moved by ``ulps`` units in the last place (toward +inf for a
    positive count), or ``x`` itself when it is 0 or not finite: the
    neighbours of 0 are subnormal, a change of no physical size."""
    x = float(x)
    if ulps == 0 or x == 0.0 or not math.isfinite(x):
        return x
    direction = math.inf if ulps > 0 else -math.inf
    for _ in range(abs(int(ulps))):
        x = math.nextafter(x, direction)
    return x


def _state_entries(data: dict):
    """(table, key, path) of every initial-state value the scene gives."""
    for sname, sub in (data.get("subsystems") or {}).items():
        if not isinstance(sub, dict):
            continue
        if sub.get("type") == "multibody":
            for bname, body in (sub.get("bodies") or {}).items():
                joint = body.get("joint") if isinstance(body, dict) else None
                if isinstance(joint, dict):
                    for key in ("q0", "dq0"):
                        if isinstance(joint.get(key), (int, float)) \
                                and not isinstance(joint.get(key), bool):
                            yield joint, key, f"subsystems.{sname}.bodies.{bname}.joint.{key}"
        elif isinstance(sub.get("initial_velocity"), (int, float)) \
                and not isinstance(sub.get("initial_velocity"), bool):
            yield sub, "initial_velocity", f"subsystems.{sname}.initial_velocity"


def state_keys(scene) -> list[str]:
    """Key paths of the nonzero initial-state values :func:`perturbed` moves."""
    return [path for table, key, path in _state_entries(scene.data) if table[key] != 0]


def perturbed_overrides(scene, ulps: int) -> list[str]:
    """The ``--set`` overrides that make :func:`perturbed`'s copy from the
    command line (``key.path=value``, each value written to round-trip)."""
    out = [f"{path}={nudge(table[key], ulps)!r}"
           for table, key, path in _state_entries(scene.data) if table[key] != 0]
    if ulps and not out:
        raise ValueError(f"{scene.path}: the scene gives no nonzero initial joint coordinate, "
                         f"joint velocity or structure velocity to move by round-off")
    return out


def perturbed(scene, ulps: int):
    """A copy of ``scene`` whose nonzero initial-state values are each moved
    by ``ulps`` ulps (:func:`nudge`), validated like the file it came from.

    Raises
    ------
    ValueError
        If the scene gives no nonzero initial value to move (``ulps`` != 0).
    """
    from cosim.scene.load import _validate

    if ulps == 0:
        return scene
    data = copy.deepcopy(scene.data)
    moved = 0
    for table, key, _ in _state_entries(data):
        if table[key] != 0:
            table[key] = nudge(table[key], ulps)
            moved += 1
    if not moved:
        raise ValueError(f"{scene.path}: the scene gives no nonzero initial joint coordinate, "
                         f"joint velocity or structure velocity to move by round-off")
    return _validate(data, Path(scene.path), scene.variant)


def spread(scene, copies: int) -> list:
    """The scene and ``copies - 1`` copies moved by :data:`OFFSETS` ulps."""
    if not 1 <= copies <= len(OFFSETS) + 1:
        raise ValueError(f"copies must be between 1 and {len(OFFSETS) + 1}, got {copies}")
    return [scene] + [perturbed(scene, k) for k in OFFSETS[:copies - 1]]
