"""The coupled system's layout as the compiled loop reads it: public,
read-only faces of the system's own arrays (no copy, no write)."""
import warnings

import numpy as np
import pytest

import cosim


def _system():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene("cases/beam_impact.toml").build()[0]


def test_the_layout_faces_are_read_only_views_of_the_system_arrays():
    system = _system()
    row_a, row_b = system.contact_rows
    faces = [row_a, row_b, system.contact_normals, system.contact_offsets,
             *system.exchange_maps]
    for a in faces:
        assert not a.flags.writeable
        with pytest.raises(ValueError):
            a[...] = 0
    assert row_a.shape == row_b.shape == (system.n_contacts,)
    assert system.contact_normals.shape == (system.n_contacts, 2)
    assert len(system.exchange_maps) == len(system.subsystems)
    for G, sub in zip(system.exchange_maps, system.subsystems):
        assert G.shape == (2 * sub.n_ports, system.n_rows)


def test_the_penetrations_from_the_faces_are_the_system_s():
    """The gap ``offset - (x_a - x_b) . n`` from the faces agrees with
    :meth:`CoupledSystem.penetrations` (same formula, evaluated apart: a few
    ulps of the offsets and positions)."""
    system = _system()
    outs = system.outputs()
    pos = np.concatenate([o[0] for o in outs])
    row_a, row_b = system.contact_rows
    d = system.contact_offsets - np.einsum("cx,cx->c", pos[row_a] - pos[row_b],
                                           system.contact_normals)
    d_sys = system.penetrations(outs)[0][:system.n_contacts]
    scale = np.abs(system.contact_offsets) + np.abs(pos).max()
    assert np.all(np.abs(d - d_sys) <= 8 * np.finfo(float).eps * scale)
