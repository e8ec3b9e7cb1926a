"""The scene's datatypes pinned to the facts other stages read from them: the kind and role
numbering (the radar's cross-section table, the viewer's and report's names, the scenarios' ego
and target rows), the frame period, and which fields are arrays and which are static."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from diffsense import scene as sc

ARRAY_FIELDS = ("s_m", "d_m", "x_m", "y_m", "heading_rad", "road_angle_rad", "speed_mps", "lane",
                "length_m", "width_m", "kind", "role", "present")


def _scene(lead: tuple[int, ...], frames: int, vehicles: int, **kw) -> sc.Scene:
    """A scene of zeros (each field its own array), with leading batch axes `lead`."""
    fields = {}
    for i, name in enumerate(ARRAY_FIELDS):
        shape = lead + ((frames, vehicles) if i < 8 else (vehicles,))  # the first 8 are per frame
        dtype = jnp.int32 if name in ("lane", "kind", "role") else jnp.bool_ if name == "present" else jnp.float64
        fields[name] = jnp.zeros(shape, dtype)
    return sc.Scene(**fields, **kw)


def test_kinds_are_numbered_in_the_order_of_their_names_and_of_the_radars_cross_sections():
    assert (sc.CAR, sc.VAN, sc.TRUCK) == (0, 1, 2)
    assert sc.KIND_NAMES == ("car", "van", "truck")
    # the radar's cross sections by kind: tests/test_radar.py


def test_roles_are_numbered_in_the_order_of_their_names_with_ego_and_target_first():
    assert (sc.EGO, sc.TARGET, sc.LEAD, sc.TARGET_LEAD, sc.ADJACENT, sc.BACKGROUND) == (0, 1, 2, 3, 4, 5)
    assert sc.ROLE_NAMES == ("ego", "target", "lead", "target_lead", "adjacent", "background")
    assert (sc.EGO_INDEX, sc.TARGET_INDEX) == (0, 1)
    assert (sc.Scene.ego_index, sc.Scene.target_index) == (0, 1)


def test_a_simulated_scenario_has_its_ego_in_row_0_and_its_target_in_row_1():
    cfg = sc.load_scenario("sc01")
    scene = sc.simulate_scenario(cfg, 2, 0)
    role = np.asarray(scene.role)
    assert role.shape == (2, scene.num_vehicles)
    np.testing.assert_array_equal(role[:, sc.EGO_INDEX], sc.EGO)
    np.testing.assert_array_equal(role[:, sc.TARGET_INDEX], sc.TARGET)
    assert (role[:, 2:] > sc.TARGET).all()  # no other row is an ego or a target
    assert sc.KIND_NAMES[int(scene.kind[0, sc.EGO_INDEX])] == cfg.ego.kind


def test_the_frame_period_is_a_static_tenth_of_a_second_and_every_other_field_a_leaf():
    scene = _scene((), 5, 3)
    assert scene.dt_s == 0.1
    leaves = jax.tree.leaves(scene)
    assert len(leaves) == len(ARRAY_FIELDS)
    assert all(leaf is getattr(scene, name) for leaf, name in zip(leaves, ARRAY_FIELDS))  # in field order
    # Static: two periods are two tree structures, so a jitted function sees the period as a
    # Python number and retraces for another one.
    assert jax.tree.structure(scene) != jax.tree.structure(_scene((), 5, 3, dt_s=0.04))
    seen = []
    jax.jit(lambda s: seen.append(type(s.dt_s)) or s.s_m)(_scene((), 5, 3, dt_s=0.04))
    assert seen == [float]


def test_frames_and_vehicles_are_counted_on_the_trailing_axes_with_or_without_a_batch():
    for lead in ((), (4,), (2, 4)):
        scene = _scene(lead, 7, 3)
        assert (scene.num_frames, scene.num_vehicles) == (7, 3)
    # vmapped over variants, each variant's scene counts the same
    counts = []
    jax.vmap(lambda s: counts.append((s.num_frames, s.num_vehicles)) or s.s_m)(_scene((4,), 7, 3))
    assert counts == [(7, 3)]
