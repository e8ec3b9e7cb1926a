"""What a sensor setting means in numbers: the boresight link budget and the coverage field.

Both are computed with the same model functions as `detect`, on probe scenes: the ego at the
origin heading +x and one probe vehicle per frame (so a whole grid is one [G, 2] scene).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from diffsense.scene import CAR, Scene
from diffsense.sensors._camera import camera_depth_sigma_m, camera_px_per_rad
from diffsense.sensors._config import RadarConfig
from diffsense.sensors._detect import Config, Params, p_detect
from diffsense.sensors._radar import radar_gain_dbi, radar_rcs_dbsm, radar_snr_db

_jit_p_detect = jax.jit(p_detect, static_argnames=("config", "mode"))
_jit_snr_db = jax.jit(radar_snr_db, static_argnames="config")
_jit_depth_sigma_m = jax.jit(camera_depth_sigma_m, static_argnames="config")


def probe_scene(x_m, y_m, *, kind: int = CAR, length_m: float, width_m: float) -> Scene:
    """Ego (4.5 m x 1.8 m car) at the origin heading +x; probe vehicle at (x_m[g], y_m[g])."""
    x = jnp.stack([jnp.zeros_like(x_m), x_m], axis=-1)
    y = jnp.stack([jnp.zeros_like(y_m), y_m], axis=-1)
    zeros = jnp.zeros_like(x)
    return Scene(
        s_m=x, d_m=y, x_m=x, y_m=y, heading_rad=zeros, road_angle_rad=zeros, speed_mps=zeros,
        lane=jnp.zeros(x.shape, jnp.int32),
        length_m=jnp.asarray([4.5, length_m], x.dtype), width_m=jnp.asarray([1.8, width_m], x.dtype),
        kind=jnp.asarray([CAR, kind], jnp.int32), role=jnp.asarray([0, 1], jnp.int32),
        present=jnp.ones((2,), bool),
    )


def swerling1_snr_db(pd: float, pfa: float) -> float:
    """The SNR [dB] at which a Swerling I target is detected with probability `pd` at false-alarm
    probability `pfa`: Pd = Pfa^(1 / (1 + SNR)) solved for SNR."""
    return 10.0 * math.log10(math.log(pfa) / math.log(pd) - 1.0)


@functools.partial(jax.jit, static_argnames="config")
def radar_snr_range_m(params, config: RadarConfig, rcs_dbsm, threshold_db=None) -> Float[Array, ""]:
    """Range [m] at which the boresight SNR of a target equals `threshold_db` (default: the
    threshold law's `snr_threshold_db`).

    Bisection in log range over [1 mm, 10^4 km] (SNR falls monotonically with range); 0 or inf
    when the threshold is crossed outside that bracket.
    """
    threshold_db = config.snr_threshold_db if threshold_db is None else threshold_db

    def margin(log_r):
        return radar_snr_db(jnp.exp(log_r), rcs_dbsm, params, config) - threshold_db

    def halve(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        above = margin(mid) > 0
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

    lo, hi = jnp.log(1e-3), jnp.log(1e7)
    lo, hi = jax.lax.fori_loop(0, 80, halve, (lo, hi))  # 80 halvings of a 23-wide log bracket
    r = jnp.exp(0.5 * (lo + hi))
    r = jnp.where(margin(jnp.log(1e-3)) <= 0, 0.0, r)
    return jnp.where(margin(jnp.log(1e7)) >= 0, jnp.inf, r)


def boresight_report(
    params: Params, config: Config, at_range_m: float, *, kind: int = CAR,
    length_m: float = 4.5, width_m: float = 1.8,
) -> dict[str, float]:
    """Numbers of one setting for a vehicle straight ahead at `at_range_m` from the sensor."""
    report: dict[str, float] = {"hfov_deg": float(params.hfov_deg), "at_range_m": at_range_m}
    scene = probe_scene(jnp.asarray([config.mount_x_m + at_range_m]), jnp.zeros(1), kind=kind,
                        length_m=length_m, width_m=width_m)
    if isinstance(config, RadarConfig):
        rcs = float(radar_rcs_dbsm(jnp.asarray(kind), config))
        snr_range = float(radar_snr_range_m(params, config, rcs))
        report |= {
            "gain_dbi": float(radar_gain_dbi(params, config)),
            "snr_db": float(_jit_snr_db(jnp.asarray(at_range_m), rcs, params, config)),
            "snr_threshold_db": config.snr_threshold_db,
            "snr_range_m": snr_range,
            "effective_range_m": min(snr_range, float(params.range_m)),
        }
        if config.detection.law == "swerling1":  # where detection is as likely as not, and likely
            pfa = config.detection.pfa
            pd50, pd90 = (float(radar_snr_range_m(params, config, rcs, swerling1_snr_db(pd, pfa))) for pd in (0.5, 0.9))
            report |= {"snr_pd50_db": swerling1_snr_db(0.5, pfa), "range_pd50_m": pd50, "range_pd90_m": pd90,
                       "effective_range_m": min(pd50, float(params.range_m))}
    else:
        k = float(camera_px_per_rad(params))
        # Where the probe's width shrinks to min_width_px: 2 atan(w / 2R) k = min_width_px.
        # (No resolvability gate, as in the paper profile: every range is resolvable.)
        half_angle = 0.5 * config.min_width_px / k
        resolvable = 0.5 * width_m / math.tan(half_angle) if half_angle > 0 else math.inf
        report |= {
            "px_per_rad": k,
            "width_px_at_range": 2.0 * math.atan2(0.5 * width_m, at_range_m) * k,
            "depth_sigma_m": float(_jit_depth_sigma_m(jnp.asarray(at_range_m), params, config)),
            "resolvable_range_m": resolvable,
            "effective_range_m": min(resolvable, float(params.range_m)),
        }
    for mode in ("soft", "hard"):
        report[f"p_detect_{mode}"] = float(_jit_p_detect(scene, params, config, mode=mode)[0, 1])
    return report


def coverage_field(
    params: Params, config: Config, x_m: np.ndarray, y_m: np.ndarray, *, mode: str = "soft",
    kind: int = CAR, length_m: float = 4.5, width_m: float = 1.8,
) -> np.ndarray:
    """p_detect [len(y_m), len(x_m)] of a lone probe vehicle at each grid point around the ego."""
    gx, gy = np.meshgrid(np.asarray(x_m, float), np.asarray(y_m, float))
    scene = probe_scene(jnp.asarray(gx.ravel()), jnp.asarray(gy.ravel()), kind=kind,
                        length_m=length_m, width_m=width_m)
    field = _jit_p_detect(scene, params, config, mode=mode)
    return np.asarray(field[:, 1]).reshape(gx.shape)
