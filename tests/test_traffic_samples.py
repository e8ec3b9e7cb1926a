"""Training samples: grid geometry, manoeuvre labels, the shard layout, determinism and the CLI."""

from __future__ import annotations

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.cli import run
from diffsense.config import to_dict
from diffsense.runtime._errors import InputError
from diffsense.cli.generate import main
from diffsense.scene._idm import IDMParams
from diffsense.train._samples import (
    BRAKING, GRID_CELL_M, KEEP, LEFT, NORMAL, RIGHT, extract_samples, lateral_label, longitudinal_label,
)
from diffsense.scene._traffic_state import TrafficTrajectories, TrafficVehicles
from diffsense.train._dataset import generate_samples, read_dataset, read_meta, samples_per_simulation
from test_traffic import CFG, small_config

LANE_W = 3.66
RING_M = 1000.0


def constructed_traffic() -> TrafficTrajectories:
    """Seven vehicles at 10 m/s for 9 s (91 frames at 10 Hz); the instant is frame 40 (t = 4 s).

    0: the target, lane 1, s = 990 + 10 t (near the ring's end).
    1: lane 2 (left), 9.2 m ahead -> cell round(9.2 / 4.572) + 6 = 8 -> grid id 0 * 13 + 8 = 8.
    2: lane 0 (right), 10 m behind -> cell -2 + 6 = 4 -> grid id 2 * 13 + 4 = 30.
    3: lane 1, 12 m ahead across the ring's seam (s wraps at 1000 m) -> grid id 13 + 9 = 22.
    4: lane 1, 40 m ahead: outside the grid (90 ft = 27.4 m).
    5: far away, changes from lane 3 to lane 2 between t = 5 s and 8 s -> lateral label right.
    6: far away in lane 0, stops at t = 4 s -> longitudinal label braking.
    """
    t = np.arange(91) * 0.1
    s = np.stack(
        [990 + 10 * t, 999.2 + 10 * t, 980 + 10 * t, 2 + 10 * t, 30 + 10 * t, 500 + 10 * t, 700 + 10 * np.minimum(t, 4.0)],
        axis=1,
    )
    lanes = np.array([1, 2, 0, 1, 1, 3, 0])
    d = np.broadcast_to((lanes + 0.5) * LANE_W, s.shape).copy()
    u = np.clip((t - 5.0) / 3.0, 0.0, 1.0)
    d[:, 5] = (3.5 - u * u * u * (10 - 15 * u + 6 * u * u)) * LANE_W
    lane = np.broadcast_to(lanes, s.shape).astype(np.int32)
    ones = jnp.ones(7, jnp.float32)
    vehicles = TrafficVehicles(
        length_m=4.5 * ones, width_m=1.8 * ones, kind=jnp.zeros(7, jnp.int32), idm=IDMParams(),
        politeness=0.2 * ones, max_desired_speed_mps=40 * ones, mean_desired_speed_mps=jnp.float32(30.0),
        ring_length_m=jnp.float32(RING_M),
    )
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    return TrafficTrajectories(
        s_m=f32(s), d_m=f32(d), speed_mps=f32(np.gradient(s, 0.1, axis=0)), lane=jnp.asarray(lane),
        target_lane=jnp.asarray(lane), vehicles=vehicles,
    )


@pytest.fixture(scope="module")
def constructed():
    extract = jax.jit(extract_samples, static_argnums=(1, 2, 3))
    return jax.tree_util.tree_map(np.asarray, extract(constructed_traffic(), LANE_W, 0.0, 1.0))


def test_neighbours_land_in_their_grid_cells(constructed):
    assert constructed.hist.shape == (7, 16, 2) and constructed.nbr_hist.shape == (7, 39, 16, 2)
    assert constructed.hist.dtype == np.float32
    occupied = np.nonzero(constructed.nbr_present[0])[0]
    assert occupied.tolist() == [8, 22, 30]
    expected_now = {8: (9.2, LANE_W), 30: (-10.0, -LANE_W), 22: (12.0, 0.0)}
    for slot, (lon, lat) in expected_now.items():
        np.testing.assert_allclose(constructed.nbr_hist[0, slot, -1], (lon, lat), atol=2e-3)
        # 3 s earlier the neighbour was 30 m further back, relative to the target *at the instant*.
        np.testing.assert_allclose(constructed.nbr_hist[0, slot, 0], (lon - 30.0, lat), atol=2e-3)
    assert (constructed.nbr_hist[0][~constructed.nbr_present[0]] == 0).all()
    # Seen from vehicle 1 (lane 2), the target is one lane right, 9.2 m behind (cell -2 + 6 = 4) and
    # vehicle 3 one lane right, 2.8 m ahead (cell 1 + 6 = 7).
    assert np.nonzero(constructed.nbr_present[1])[0].tolist() == [2 * 13 + 4, 2 * 13 + 7]


def test_target_history_and_future_in_the_road_frame(constructed):
    np.testing.assert_allclose(constructed.hist[0, :, 0], np.arange(-15, 1) * 2.0, atol=2e-3)  # 10 m/s at 5 Hz
    np.testing.assert_allclose(constructed.fut[0, :, 0], np.arange(1, 26) * 2.0, atol=2e-3)
    assert (constructed.hist[0, -1] == 0).all() and (constructed.hist[0, :, 1] == 0).all()
    # The lane changer moves right: its future lateral offset reaches minus one lane width, along
    # the constructed smoothstep, point by point (t = 4.2 ... 9 s).
    u = np.clip((4.0 + 0.2 * np.arange(1, 26) - 5.0) / 3.0, 0.0, 1.0)
    np.testing.assert_allclose(constructed.fut[5, :, 1], -u**3 * (10 - 15 * u + 6 * u**2) * LANE_W, atol=1e-3)
    np.testing.assert_allclose(constructed.fut[5, -1, 1], -LANE_W, atol=1e-3)


def test_every_instant_reads_its_own_future():
    """The constructed scene one second longer (everyone keeps going): instants at 4 s and 5 s; the
    first is not at the recording's end, so a future window read one point late would show."""
    traffic = constructed_traffic()
    more = np.arange(1, 11, dtype=np.float32) * 0.1

    def extend(a, step=None):
        tail = a[-1:] if step is None else a[-1:] + more[:, None] * step
        return jnp.concatenate([a, jnp.broadcast_to(tail, (10, a.shape[1]))])

    longer = TrafficTrajectories(s_m=extend(traffic.s_m, traffic.speed_mps[-1]), d_m=extend(traffic.d_m),
                                 speed_mps=extend(traffic.speed_mps), lane=extend(traffic.lane),
                                 target_lane=extend(traffic.target_lane), vehicles=traffic.vehicles)
    got = extract_samples(longer, LANE_W, 1.0, 1.0)  # rows: instant * 7 + vehicle
    u = np.clip((4.0 + 0.2 * np.arange(1, 26) - 5.0) / 3.0, 0.0, 1.0)
    np.testing.assert_allclose(np.asarray(got.fut[5, :, 1]), -u**3 * (10 - 15 * u + 6 * u**2) * LANE_W, atol=1e-3)
    np.testing.assert_allclose(np.asarray(got.fut[7, :, 0]), np.arange(1, 26) * 2.0, atol=2e-3)


def test_of_two_vehicles_in_one_cell_the_one_nearer_its_centre_is_kept():
    """Target 0 and, in its lane, vehicles 12.5 m and 13.6 m ahead: both in cell round(x / 4.572)
    + 6 = 9 (centre 13.716 m); vehicle 2, the nearer the centre, is kept though its index is higher."""
    traffic = constructed_traffic()

    def pick(a):  # three vehicles, all in lane 1
        return a[:, [0, 3, 4]]

    t = jnp.arange(91, dtype=jnp.float32) * 0.1
    s = jnp.stack([100 + 10 * t, 112.5 + 10 * t, 113.6 + 10 * t], axis=1)
    three = TrafficTrajectories(s_m=s, d_m=pick(traffic.d_m), speed_mps=pick(traffic.speed_mps), lane=pick(traffic.lane),
                                target_lane=pick(traffic.target_lane),
                                vehicles=jax.tree_util.tree_map(lambda a: a[:3] if jnp.ndim(a) else a,
                                                                   traffic.vehicles))  # all alike
    got = extract_samples(three, LANE_W, 0.0, 1.0)
    assert np.nonzero(np.asarray(got.nbr_present[0]))[0].tolist() == [13 + 9]
    np.testing.assert_allclose(np.asarray(got.nbr_hist[0, 13 + 9, -1]), (13.6, 0.0), atol=2e-3)


def test_labels_of_the_constructed_scene(constructed):
    assert constructed.lat_label.tolist() == [KEEP, KEEP, KEEP, KEEP, KEEP, RIGHT, KEEP]
    assert constructed.lon_label.tolist() == [NORMAL] * 6 + [BRAKING]


@pytest.mark.parametrize(
    "before, now, after, label",
    [
        (1, 1, 1, KEEP), (1, 1, 2, LEFT), (1, 1, 0, RIGHT), (0, 1, 1, LEFT), (2, 1, 1, RIGHT),
        (0, 1, 0, RIGHT),  # both ways within 4 s: the reference checks "right" first
        (2, 1, 2, RIGHT),
    ],
)
def test_lateral_label_rule(before, now, after, label):
    assert int(jax.jit(lateral_label)(jnp.asarray(before), jnp.asarray(now), jnp.asarray(after))) == label


@pytest.mark.parametrize(
    "s_before, s_now, s_after, label",
    [
        (0.0, 30.0, 80.0, NORMAL),  # 10 m/s then 10 m/s
        (0.0, 30.0, 69.0, BRAKING),
        (0.0, 30.0, 71.0, NORMAL),
        (5.0, 5.0, 5.0, NORMAL),  # standing still is not braking
    ],
)
def test_longitudinal_label_rule(s_before, s_now, s_after, label):
    got = jax.jit(longitudinal_label)(jnp.float32(s_before), jnp.float32(s_now), jnp.float32(s_after))
    assert int(got) == label


NUM = 3 * samples_per_simulation(CFG) + 50  # four simulations (one batch), the last one truncated


@pytest.fixture(scope="module")
def dataset():
    return generate_samples(CFG, NUM, jax.random.key(11))


def test_dataset_layout(dataset):
    s, m = len(dataset["hist"]), len(dataset["nbr_hist"])
    assert s == NUM and m > s
    assert dataset["hist"].dtype == np.float32 and dataset["hist"].shape == (s, 16, 2)
    assert dataset["fut"].shape == (s, 25, 2) and dataset["nbr_hist"].shape == (m, 16, 2)
    assert dataset["nbr_sample"].dtype == np.int32 and dataset["nbr_slot"].dtype == np.int8
    assert dataset["lat_label"].dtype == np.int8 and dataset["lon_label"].dtype == np.int8
    assert (np.diff(dataset["nbr_sample"]) >= 0).all() and dataset["nbr_sample"].max() < s
    assert 0 <= dataset["nbr_slot"].min() and dataset["nbr_slot"].max() < 39
    assert dataset["sim_id"].tolist() == sorted(dataset["sim_id"].tolist()) and dataset["sim_id"].max() == 3
    assert np.isfinite(dataset["nbr_hist"]).all() and (dataset["hist"][:, -1] == 0).all()
    # Each neighbour's last history point is within the grid of its sample's target.
    lon_now, lat_now = dataset["nbr_hist"][:, -1, 0], dataset["nbr_hist"][:, -1, 1]
    cell = dataset["nbr_slot"] % 13
    lane = dataset["nbr_slot"] // 13
    np.testing.assert_array_equal(np.round(lon_now / GRID_CELL_M) + 6, cell)
    assert (np.sign(np.round(lat_now / LANE_W)) == 1 - lane).all()
    # No (sample, slot) twice.
    pairs = dataset["nbr_sample"].astype(np.int64) * 39 + dataset["nbr_slot"]
    assert len(np.unique(pairs)) == m


def test_same_seed_same_samples_bit_for_bit(dataset):
    again = generate_samples(CFG, NUM, jax.random.key(11))
    for k in dataset:
        np.testing.assert_array_equal(dataset[k], again[k], err_msg=k)
    assert not np.array_equal(generate_samples(CFG, NUM, jax.random.key(12))["hist"], dataset["hist"])


def test_samples_do_not_depend_on_the_batching(dataset):
    # Batches of two over four simulations: the fast tests elsewhere batch one at a time, where a
    # batch launched at every simulation instead of every second one cannot show.
    cfg = small_config(simulations_per_shard=2)
    other = generate_samples(cfg, NUM, jax.random.key(11))
    for k in dataset:
        np.testing.assert_array_equal(dataset[k], other[k], err_msg=k)


def _toml(table: dict, prefix: str = "") -> str:
    """Enough of a TOML writer for a config dict (numbers, strings, lists, nested tables)."""
    lines, subs = [], []
    for k, v in table.items():
        if isinstance(v, dict):
            subs.append(f"\n[{prefix}{k}]\n" + _toml(v, f"{prefix}{k}."))
        else:
            lines.append(f"{k} = {v!r}".replace("(", "[").replace(")", "]").replace("'", '"'))
    return "\n".join(lines) + "".join(subs) + "\n"


def test_cli_writes_a_readable_dataset(tmp_path, monkeypatch, dataset, capsys):
    monkeypatch.setenv("DIFFSENSE_NO_CACHE", "1")
    config = tmp_path / "traffic.toml"
    config.write_text(_toml(to_dict(CFG)))
    out = tmp_path / "set"
    assert main(["--config", str(config), "--out", str(out), "--samples", str(NUM), "--seed", "11", "--no-progress"]) == 0
    assert f"wrote {NUM} samples" in capsys.readouterr().out
    meta = read_meta(out)
    assert meta["num_samples"] == NUM and meta["seed"] == 11 and meta["config"] == to_dict(small_config(num_samples=NUM, seed=11))
    assert sum(meta["lat_label_counts"].values()) == NUM
    shards = list(read_dataset(out))
    assert len(shards) == len(meta["shards"]) == 1  # four simulations, one shard
    for k in dataset:
        np.testing.assert_array_equal(shards[0][k], dataset[k], err_msg=k)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["set", "traffic.toml"]  # no temporary left
    with pytest.raises(SystemExit) as e:  # never overwrites a dataset
        run(lambda: main(["--config", str(config), "--out", str(out), "--samples", "10"]))
    assert e.value.code == 2 and "already exists" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_process_without_x64_writes_the_same_samples(tmp_path, dataset):
    # The tests run with jax_enable_x64; `python -m diffsense.scene generate` without: same bits.
    config = tmp_path / "traffic.toml"
    config.write_text(_toml(to_dict(CFG)))
    out = tmp_path / "set"
    proc = subprocess.run(
        [sys.executable, "-m", "diffsense.scene", "generate", "--config", str(config), "--out", str(out),
         "--samples", str(NUM), "--seed", "11", "--no-progress"],
        capture_output=True, text=True, timeout=600, env=dict(os.environ, DIFFSENSE_NO_CACHE="1"),
    )
    assert proc.returncode == 0, proc.stderr
    (shard,) = read_dataset(out)
    for k in dataset:
        np.testing.assert_array_equal(shard[k], dataset[k], err_msg=k)


def test_reading_refuses_broken_datasets(tmp_path, dataset):
    with pytest.raises(InputError, match="no meta.json"):
        list(read_dataset(tmp_path))
    bad = dict(dataset, hist=np.where(np.arange(NUM)[:, None, None] == 3, np.nan, dataset["hist"]).astype(np.float32))
    np.savez(tmp_path / "shard_00000.npz", **bad)
    (tmp_path / "meta.json").write_text('{"layout_version": 1, "shards": [{"file": "shard_00000.npz"}]}')
    with pytest.raises(InputError, match="NaN"):
        list(read_dataset(tmp_path))
    np.savez(tmp_path / "shard_00000.npz", **dict(dataset, lat_label=np.full(NUM, 3, np.int8)))
    with pytest.raises(InputError, match="labels out of range"):
        list(read_dataset(tmp_path))
    np.savez(tmp_path / "shard_00000.npz", **dict(dataset, nbr_slot=dataset["nbr_slot"].astype(np.int64)))
    with pytest.raises(InputError, match="nbr_slot is int64"):
        list(read_dataset(tmp_path))


@pytest.mark.parametrize(
    "text, needle",
    [
        ("[road]\nnum_lanes = 3\nlanes_wide = 2\n", "unknown key 'road.lanes_wide'"),
        ("[traffic]\ndensity_veh_per_km_lane = [60.0, 10.0]\n", "reversed interval"),
        ("[sampling]\nwarmup_s = 'long'\n", "sampling.warmup_s"),
        ("[road\n", "malformed TOML"),
    ],
)
def test_cli_rejects_bad_config_with_one_line_and_exit_2(tmp_path, text, needle):
    config = tmp_path / "bad.toml"
    config.write_text(text)
    out = tmp_path / "set"
    proc = subprocess.run(
        [sys.executable, "-m", "diffsense.cli.generate", "--config", str(config), "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: ") and needle in proc.stderr
    assert not out.exists()


def test_cli_rejects_bad_arguments(tmp_path, capsys):
    for argv, needle in [(["--out", str(tmp_path / "a"), "--samples", "0"], "num_samples"), (["--out"], "--out"), (["--out", str(tmp_path / "b"), "--bogus"], "bogus")]:
        with pytest.raises(SystemExit) as e:
            run(lambda: main(argv))
        err = capsys.readouterr().err
        assert e.value.code == 2 and err.count("\n") == 1 and needle in err, err
