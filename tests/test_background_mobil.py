"""Background traffic's MOBIL decision (`lane_change_starts`) restated as plain loops, and pinned
on hand-built scenes; and the scenario simulation's leader search (`leaders`) against loops.

The restatement follows the module's docstring one vehicle at a time: the nearest vehicle ahead
and behind in a lane (occupying it now, or heading into it; abreast counts as ahead), the old
follower re-following c's leader, both sides (left first), a bumper gap above s0 to both new
neighbours, MOBIL's safety and incentive with the keep-right bias, and one starter per scene (the
largest incentive, the lower index on a tie). The IDM acceleration comes from the library (pinned
by hand in tests/test_idm_mobil.py). The hand scenes check what a driver does. These two private
functions are the traffic rules under test; tests/test_scene_simulation.py reuses the loops.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.scene import FREE_ROAD_GAP_M, IDMParams, MOBILParams, idm_acceleration
from diffsense.scene._background_mobil import lane_change_starts
from diffsense.scene._simulate import leaders

W = 3.5  # lane width [m]
LANES = 3
# Per-vehicle desired speed and headway (as the scene's IDM has them), the rest scalars: a field
# taken from the wrong vehicle changes a value.
IDM_FIELDS = ("desired_speed_mps", "time_headway_s", "min_gap_m", "max_accel_mps2", "comfort_decel_mps2",
              "accel_exponent")
MOBIL = MOBILParams(politeness=jnp.asarray(0.35), threshold_mps2=jnp.asarray(0.15),
                    safe_decel_mps2=jnp.asarray(3.0), keep_right_bias_mps2=jnp.asarray(0.1))


def idm_params(v0, headway):
    return IDMParams(desired_speed_mps=jnp.asarray(v0, float), time_headway_s=jnp.asarray(headway, float),
                     min_gap_m=jnp.asarray(2.2), max_accel_mps2=jnp.asarray(1.1),
                     comfort_decel_mps2=jnp.asarray(1.6), accel_exponent=jnp.asarray(4.0))


def vehicle_idm(p: IDMParams, j: int) -> IDMParams:
    return IDMParams(*(float(np.asarray(getattr(p, f))[j]) if np.ndim(getattr(p, f)) else float(getattr(p, f))
                       for f in IDM_FIELDS))


def call(scene, idm, free, mobil=MOBIL, lanes=LANES):
    s, d, centre, v, a, length = (jnp.asarray(scene[k], float) for k in ("s", "d", "centre", "v", "a", "length"))
    starts, to = jax.jit(lane_change_starts)(s, d, centre, v, a, length, idm, jnp.asarray(free), jnp.asarray(W),
                                             jnp.asarray(lanes), mobil)
    return np.asarray(starts), np.asarray(to)


def ref_nearest(c, lane_centre, scene, ahead, lane_w=W):
    """(j, bumper gap) of the nearest other vehicle ahead of (or behind) c in the lane centred at
    `lane_centre` (its centre or its target within half a lane); (None, FREE) when there is none."""
    s, d, centre, length = scene["s"], scene["d"], scene["centre"], scene["length"]
    best, who = FREE_ROAD_GAP_M, None
    for j in range(len(s)):
        there = abs(d[j] - lane_centre) < 0.5 * lane_w or abs(centre[j] - lane_centre) < 0.5 * lane_w
        side = s[j] >= s[c] if ahead else s[j] < s[c]
        gap = abs(s[j] - s[c]) - 0.5 * (length[j] + length[c])
        if j != c and there and side and gap < best:
            best, who = gap, j
    return who, best


def ref_sides(c, scene, idm, mobil=MOBIL, lanes=LANES, lane_w=W):
    """Per side (left first): (lane centre, own gain, followers' gain, admissible), c's MOBIL
    incentive being own + politeness * followers'; admissible: the lane exists, both new bumper
    gaps exceed s0 and the new follower brakes no harder than b_safe."""
    s, centre, v, a, length = scene["s"], scene["centre"], scene["v"], scene["a"], scene["length"]
    me = vehicle_idm(idm, c)
    leader, _ = ref_nearest(c, centre[c], scene, True, lane_w)
    old_f, _ = ref_nearest(c, centre[c], scene, False, lane_w)
    old_gain = 0.0
    if old_f is not None:  # it follows c's leader once c has gone
        gap = FREE_ROAD_GAP_M if leader is None else s[leader] - s[old_f] - 0.5 * (length[leader] + length[old_f])
        lead_v = v[leader] if leader is not None else v[0]
        old_gain = float(idm_acceleration(v[old_f], gap, lead_v, vehicle_idm(idm, old_f))) - a[old_f]
    lane, sides = math.floor(centre[c] / lane_w), []
    for side in (1, -1):
        target = centre[c] + side * lane_w
        new_l, l_gap = ref_nearest(c, target, scene, True, lane_w)
        new_f, f_gap = ref_nearest(c, target, scene, False, lane_w)
        own_after = float(idm_acceleration(v[c], l_gap, v[new_l if new_l is not None else 0], me))
        f_now = f_after = 0.0
        if new_f is not None:
            f_after = float(idm_acceleration(v[new_f], f_gap, v[c], vehicle_idm(idm, new_f)))
            f_now = a[new_f]
        admissible = (0 <= lane + side <= lanes - 1 and l_gap > me.min_gap_m and f_gap > me.min_gap_m
                      and f_after >= -float(mobil.safe_decel_mps2))
        sides.append((target, own_after - a[c], f_after - f_now + old_gain, admissible))
    return sides


def ref_starts(scene, idm, free, mobil=MOBIL, lanes=LANES, lane_w=W):
    """(starts [V], lane centre heading to [V]) written out vehicle by vehicle."""
    pol, thr, bias = (float(x) for x in (mobil.politeness, mobil.threshold_mps2, mobil.keep_right_bias_mps2))
    n = len(scene["s"])
    best, to = [-math.inf] * n, list(scene["centre"])
    for c in range(n):
        for (target, own, others, admissible), side_bias in zip(ref_sides(c, scene, idm, mobil, lanes, lane_w),
                                                                (bias, -bias)):
            incentive = own + pol * others
            if free[c] and admissible and incentive > thr + side_bias and incentive > best[c]:
                best[c], to[c] = incentive, target
    first = max(range(n), key=lambda c: (best[c], -c))
    starts = np.array([c == first and math.isfinite(best[c]) for c in range(n)])
    return starts, np.array(to)


def random_scene(seed, n=7):
    rng = np.random.default_rng(seed)
    lane = rng.integers(0, LANES, n)
    heading = np.clip(lane + rng.choice([-1, 0, 0, 0, 1], n), 0, LANES - 1)  # a few change lanes
    centre = (heading + 0.5) * W
    progress = np.where(heading != lane, rng.uniform(0.1, 0.9, n), 0.0)
    d = (lane + 0.5) * W + progress * (heading - lane) * W + rng.uniform(-0.3, 0.3, n)
    scene = {"s": rng.uniform(0.0, 90.0, n), "d": d, "centre": centre, "v": rng.uniform(14.0, 32.0, n),
             "a": rng.uniform(-2.5, 1.0, n), "length": rng.choice([4.5, 5.2, 12.0], n)}
    idm = idm_params(rng.uniform(25.0, 36.0, n), rng.uniform(0.9, 1.8, n))
    return scene, idm, rng.uniform(size=n) < 0.8


def test_random_scenes_match_the_loops_and_both_sides_are_taken():
    sides = set()
    for seed in range(40):
        scene, idm, free = random_scene(seed)
        starts, to = call(scene, idm, free)
        want_starts, want_to = ref_starts(scene, idm, free)
        np.testing.assert_array_equal(starts, want_starts, err_msg=f"seed {seed}")
        np.testing.assert_allclose(to, want_to, rtol=0, atol=1e-12, err_msg=f"seed {seed}")
        if starts.any():
            c = int(np.argmax(starts))
            sides.add(int(np.sign(to[c] - scene["centre"][c])))
    assert sides == {-1, 1}  # the scenes exercise left and right changes


def hand_scene(*vehicles, min_gap_m=2.2):
    """Vehicles (s [m], lane, v [m/s], length [m]) in their lanes, each accelerating as IDM has it
    towards its leader now; every vehicle wants 33 m/s with a 1.2 s headway."""
    s, lane, v, length = (np.array(x, float) for x in zip(*vehicles))
    centre = (lane + 0.5) * W
    scene = {"s": s, "d": centre, "centre": centre, "v": v, "length": length, "a": np.zeros(len(s))}
    idm = dataclasses.replace(idm_params([33.0] * len(s), [1.2] * len(s)), min_gap_m=jnp.asarray(min_gap_m))
    for c in range(len(s)):
        leader, gap = ref_nearest(c, centre[c], scene, ahead=True)
        scene["a"][c] = float(idm_acceleration(v[c], gap, v[leader if leader is not None else c], vehicle_idm(idm, c)))
    return scene, idm


def mobil(bias_mps2):
    return MOBILParams(MOBIL.politeness, MOBIL.threshold_mps2, MOBIL.safe_decel_mps2, jnp.asarray(bias_mps2))


# A car at 30 m/s closing on a 20 m/s truck 21.75 m ahead in the right lane brakes hard now.
CAR_BEHIND_TRUCK = ((0.0, 0, 30.0, 4.5), (30.0, 0, 20.0, 12.0))


def test_a_car_blocked_by_a_truck_overtakes_and_only_it_starts():
    scene, idm = hand_scene(*CAR_BEHIND_TRUCK)
    assert scene["a"][0] < -5.0
    # The truck gains only politely (0.35 of the car's relief) by moving left itself: the car goes.
    starts, to = call(scene, idm, [True, True])
    np.testing.assert_array_equal(starts, [True, False])
    assert to[0] == 1.5 * W
    # On a two-lane road the left lane is the top one; on a one-lane road there is nowhere to go.
    np.testing.assert_array_equal(call(scene, idm, [True, True], lanes=2)[0], [True, False])
    np.testing.assert_array_equal(call(scene, idm, [True, True], lanes=1)[0], [False, False])
    # A scripted (not free) car stays; then the truck, free, moves over to let it pass.
    starts, to = call(scene, idm, [False, True])
    np.testing.assert_array_equal(starts, [False, True])
    assert to[1] == 1.5 * W
    np.testing.assert_array_equal(call(scene, idm, [False, False])[0], [False, False])


def test_no_change_that_makes_the_new_follower_brake_harder_than_b_safe():
    # 3.5 m behind the car's new place, 3 m/s faster: IDM brakes it far beyond 3 m/s2.
    scene, idm = hand_scene(*CAR_BEHIND_TRUCK, (-8.0, 1, 33.0, 4.5))
    np.testing.assert_array_equal(call(scene, idm, [True, False, False])[0], [False, False, False])
    # 60 m back the same follower would hardly brake: the car goes.
    scene, idm = hand_scene(*CAR_BEHIND_TRUCK, (-60.0, 1, 33.0, 4.5))
    starts, to = call(scene, idm, [True, False, False])
    np.testing.assert_array_equal(starts, [True, False, False])
    assert to[0] == 1.5 * W


@pytest.mark.parametrize(("lane", "bias", "heads_to"), [
    (1, 0.1, None),  # no gain on a free road: 0 > a_th - bias = 0.05 fails, it stays
    (1, 0.2, 0),     # 0 > -0.05: keep right wins over the threshold
    (0, 0.2, None),  # already in the rightmost lane
    (2, 0.2, 1),
])
def test_keep_right_on_a_free_road(lane, bias, heads_to):
    scene, idm = hand_scene((0.0, lane, 30.0, 4.5))
    starts, to = call(scene, idm, [True], mobil(bias))
    assert starts[0] == (heads_to is not None)
    assert to[0] == ((heads_to + 0.5) * W if heads_to is not None else (lane + 0.5) * W)


@pytest.mark.parametrize(("ahead_m", "behind_m", "goes"), [
    (6.0, 40.0, False),  # new leader's bumper gap exactly s0 = 2 m
    (6.5, 40.0, True),
    (60.0, -6.0, False),  # new follower's gap exactly s0
    (60.0, -6.5, True),
])
def test_a_change_needs_more_than_s0_to_both_new_neighbours(ahead_m, behind_m, goes):
    # The new leader drives away at 40 m/s; the new follower at the car's 30 m/s.
    scene, idm = hand_scene((0.0, 0, 30.0, 4.0), (21.0, 0, 15.0, 4.0), (ahead_m, 1, 40.0, 4.0),
                            (behind_m, 1, 30.0, 4.0), min_gap_m=2.0)
    if ahead_m == 60.0:
        scene["v"][3] = 25.0  # a slower new follower: no braking for the car that cuts in
    starts, _ = call(scene, idm, [True, False, False, False])
    assert starts[0] == goes


def test_the_decision_flips_where_the_incentive_crosses_the_threshold():
    """For each vehicle with one admissible side, the politeness p* at which own + p* x followers'
    gain equals a_th + bias: 1e-6 to one side of p* it goes, to the other it stays. This pins the
    incentive, the old follower's re-following included, to a millionth of the followers' term."""
    tried = 0
    for seed in range(40):
        scene, idm, _ = random_scene(seed)
        for c in range(len(scene["s"])):
            sides = ref_sides(c, scene, idm)
            if sum(side[3] for side in sides) != 1:
                continue
            k = [side[3] for side in sides].index(True)
            target, own, others, _ = sides[k]
            threshold = float(MOBIL.threshold_mps2) + (1, -1)[k] * float(MOBIL.keep_right_bias_mps2)
            if abs(others) < 0.05 or not 0.0 < (threshold - own) / others < 3.0:
                continue
            p_star, free = (threshold - own) / others, np.arange(len(scene["s"])) == c
            for shift in (1e-6, -1e-6):
                p = MOBILParams(jnp.asarray(p_star * (1 + shift)), *(MOBIL.threshold_mps2, MOBIL.safe_decel_mps2,
                                                                     MOBIL.keep_right_bias_mps2))
                starts, to = call(scene, idm, free, p)
                assert starts[c] == ((shift > 0) == (others > 0)), (seed, c, shift)
                assert to[c] == (target if starts[c] else scene["centre"][c])
            tried += 1
    assert tried >= 10


# The scenario simulation's leaders: each vehicle follows the nearest vehicle ahead whose body,
# widened by the lateral margin, overlaps its own, or that heads into its lane (or it into theirs).
def ref_leaders(s, d, v, length, width, margin, heading_to=None, lane_width=0.0):
    """(gap [m], leader speed [m/s]) per vehicle: the nearest j ahead (at equal s, the higher
    index) whose widened body overlaps, or which heads into i's lane, or into whose lane i heads."""
    n = len(s)
    gap, lead_v = np.full(n, FREE_ROAD_GAP_M), np.array(v, dtype=float)
    for i in range(n):
        best, who = FREE_ROAD_GAP_M, None
        for j in range(n):
            ahead = s[j] - s[i]
            in_front = ahead > 0 or (ahead == 0 and j > i)
            same = abs(d[j] - d[i]) < 0.5 * (width[i] + width[j]) + 2.0 * margin
            if heading_to is not None:
                same = same or abs(heading_to[j] - d[i]) < 0.5 * lane_width
                same = same or abs(d[j] - heading_to[i]) < 0.5 * lane_width
            g = ahead - 0.5 * (length[i] + length[j])
            if in_front and same and g < best:
                best, who = g, j
        gap[i] = best
        if best < FREE_ROAD_GAP_M:
            lead_v[i] = v[who]
    return gap, lead_v


def test_leaders_are_the_nearest_overlapping_vehicles_ahead():
    rng = np.random.default_rng(3)
    for trial in range(40):
        n = 7
        s = np.round(rng.uniform(0.0, 60.0, n), 0)  # rounded: equal s happen (ties go to the higher index)
        d = rng.choice([1.83, 5.49, 9.15], n) + rng.uniform(-1.5, 1.5, n)
        v, length, width = rng.uniform(5.0, 30.0, n), rng.uniform(4.0, 12.0, n), rng.uniform(1.6, 2.6, n)
        heading_to = np.where(rng.uniform(size=n) < 0.4, rng.choice([1.83, 5.49, 9.15], n), d)
        margin = rng.uniform(0.0, 0.6)
        for kwargs in ({}, {"heading_to": heading_to, "lane_width": W}):
            want = ref_leaders(s, d, v, length, width, margin, **kwargs)
            jkw = {"heading_to_m": jnp.asarray(kwargs["heading_to"]), "lane_width_m": W} if kwargs else {}
            got = leaders(*(jnp.asarray(x) for x in (s, d, v, length, width)), margin, **jkw)
            np.testing.assert_allclose(np.asarray(got[0]), want[0], rtol=1e-12, err_msg=f"gap, trial {trial} {kwargs and 'heading'}")
            np.testing.assert_allclose(np.asarray(got[1]), want[1], rtol=1e-12, err_msg=f"speed, trial {trial}")


def test_a_tie_in_s_goes_to_the_higher_index_and_touching_bodies_overlap_only_inside_the_margin():
    s, v, length = np.array([50.0, 50.0, 70.0]), np.array([20.0, 22.0, 24.0]), np.full(3, 4.0)
    width = np.full(3, 2.0)
    # 0 and 1 side by side, 2.4 m apart: with a 0.25 m margin their bodies (2 m + 0.5 m) overlap.
    d = np.array([0.0, 2.4, 0.0])
    gap, lead_v = leaders(*(jnp.asarray(x) for x in (s, d, v, length, width)), 0.25)
    np.testing.assert_allclose(np.asarray(gap), [-4.0, 16.0, FREE_ROAD_GAP_M])  # 0 follows 1 at equal s
    np.testing.assert_allclose(np.asarray(lead_v), [22.0, 24.0, 24.0])
    # 2.5 m apart is exactly the widened overlap: not the same lane (strict <); 0 follows 2.
    gap, lead_v = leaders(*(jnp.asarray(x) for x in (s, np.array([0.0, 2.5, 0.0]), v, length, width)), 0.25)
    np.testing.assert_allclose(np.asarray(gap), [16.0, FREE_ROAD_GAP_M, FREE_ROAD_GAP_M])
    np.testing.assert_allclose(np.asarray(lead_v), [24.0, 22.0, 24.0])
    # Heading into a lane (3.5 m lanes: every number below is exact in binary): exactly half a
    # lane away is not into it (strict <), whether j heads into i's lane or i into j's.
    for shift, inside in ((1.75, False), (1.7499, True)):
        # j = 1, 20 m to the side, heads to `shift` m from i = 0's centre; 2 is 0's leader.
        gap, _ = leaders(*(jnp.asarray(x) for x in (s, np.array([0.0, 20.0, 0.0]), v, length, width)), 0.25,
                         heading_to_m=jnp.asarray([0.0, shift, 0.0]), lane_width_m=3.5)
        assert float(gap[0]) == (-4.0 if inside else 16.0), shift
        # i = 0 heads to `shift` m from j = 1's centre (20 m to the side); 2 is out of the way.
        gap, _ = leaders(*(jnp.asarray(x) for x in (s, np.array([0.0, 20.0, 10.0]), v, length, width)), 0.25,
                         heading_to_m=jnp.asarray([20.0 - shift, 20.0, 10.0]), lane_width_m=3.5)
        assert float(gap[0]) == (-4.0 if inside else FREE_ROAD_GAP_M), shift
