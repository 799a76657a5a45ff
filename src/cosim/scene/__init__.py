"""Scene files: load and check a TOML scene, build its coupled system, describe
it (``cosim info``) and run it.

``read`` (the file, its variants, ``--set``) -> ``load`` (validation, with
``subsystems``, ``contacts`` and the table of keys in ``keys``) -> ``specs``
(frozen, typed) -> ``build`` (subsystems, contacts, scheme) -> ``run``.
``from cosim.scene import load_scene`` is the loader of :mod:`cosim.scene.load`.
"""
from cosim.scene.load import Scene, SceneError, load_scene

__all__ = ["Scene", "SceneError", "load_scene"]
