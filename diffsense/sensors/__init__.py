"""Sensors: the `Sensor` protocol, radar and stereo camera, soft (differentiable) and hard.

    radar = ds.sensors.Radar.from_toml()                       # shipped constants (or a user TOML)
    det = radar.detect(scene, {"hfov_deg": 45.0}, key)        # Detections [T, V]
    ds.sensors.register("lidar", Lidar.from_toml)             # a new sensor: one file plus a name

Lower-level physics entry points: `detect(scene, params, config, key, mode=...)` -> `Detections` [T, V] (and
`detect_batch` over [N, T, V]); `p_detect` for the probabilities alone. Parameters r are small
pytrees (`RadarParams`, `CameraParams`); constants come from `configs/sensors/*.toml` via
`load_config`. `param_specs` lists a sensor's differentiable parameters with their domains,
the mounting (`MOUNT_NAMES`: yaw_deg, mount_x_m, mount_y_m) among them.
"""

from diffsense.sensors._camera import (
    Camera,
    camera_depth_sigma_m,
    camera_detect,
    camera_p_detect,
    camera_px_per_rad,
)
from diffsense.sensors._config import (
    CameraConfig,
    CameraTemperatures,
    RadarConfig,
    RadarTemperatures,
    load_config,
    make_params,
    param_specs,
)
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._detect import detect, detect_batch, p_detect
from diffsense.sensors._fusion import Suite, fuse_members
from diffsense.sensors._gates import MODES
from diffsense.sensors._inspect import boresight_report, coverage_field
from diffsense.sensors._measure import measurement_noise
from diffsense.sensors._mount import MOUNT_NAMES, Mount, relevance_stand_ins
from diffsense.sensors._names import resolve_name, resolve_params
from diffsense.sensors._params import (
    SENSORS,
    CameraParams,
    ParamSpec,
    RadarParams,
    check_params,
    with_param,
)
from diffsense.sensors._radar import (
    Radar,
    radar_detect,
    radar_gain_dbi,
    radar_p_detect,
    radar_rcs_dbsm,
    radar_snr_db,
)
from diffsense.sensors._registry import make_sensor, register, sensor_names
from diffsense.sensors._sensor import Sensor
from diffsense.sensors._weather import CLEAR, Weather

__all__ = [
    "CLEAR", "Camera", "boresight_report", "coverage_field", "Radar", "Sensor", "Suite", "fuse_members", "Weather", "make_sensor", "register", "sensor_names",
    "MODES", "MOUNT_NAMES", "Mount", "SENSORS", "CameraConfig", "CameraParams", "CameraTemperatures", "Detections",
    "ParamSpec", "RadarConfig", "RadarParams", "RadarTemperatures", "camera_depth_sigma_m",
    "camera_detect", "camera_p_detect", "camera_px_per_rad", "check_params", "detect",
    "detect_batch", "load_config", "make_params", "measurement_noise", "p_detect", "param_specs",
    "radar_detect",
    "radar_gain_dbi", "relevance_stand_ins", "radar_p_detect", "radar_rcs_dbsm", "radar_snr_db", "resolve_name", "resolve_params",
    "with_param",
]
