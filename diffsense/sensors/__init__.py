"""Sensors: the `Sensor` protocol, radar and stereo camera, soft (differentiable) and hard.

    radar = ds.sensors.Radar.from_toml()                       # shipped constants (or a user TOML)
    det = radar.detect(scene, {"hfov_deg": 45.0}, key)        # Detections [T, V]
    ds.sensors.register("lidar", Lidar.from_toml)             # a new sensor: one file plus a name

Lower-level physics entry points: `detect(scene, params, config, key, mode=...)` -> `Detections` [T, V] (and
`detect_batch` over [N, T, V]); `p_detect` for the probabilities alone. Parameters r are small
pytrees (`RadarParams`, `CameraParams`); constants come from `configs/sensors/*.toml` via
`load_config`. `param_specs` lists a sensor's differentiable parameters with their domains,
the mounting (`MOUNT_NAMES`: yaw_deg, mount_x_m, mount_y_m) among them. The probabilistic
detection laws (`RadarDetection`, `CameraDetection`: Swerling I, detector confidence) and the
weather physics (ITU-R P.838-3 rain, Koschmieder contrast) are exported as plain functions; a
custom sensor joins a `Suite` by returning its measurement `Covariance`.
"""

from diffsense.sensors._camera import (
    Camera,
    camera_accuracy_px_per_rad,
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
from diffsense.sensors._inspect import boresight_report, coverage_field, probe_scene
from diffsense.sensors._laws import (
    CameraDetection,
    RadarDetection,
    confidence_mean,
    gaussian_beam_loss_db,
    in_fov_fraction,
    log_confidence_above,
    log_reported_below,
    swerling1_log_pd,
)
from diffsense.sensors._measure import measurement_noise
from diffsense.sensors._member import VARIANCE_FLOOR_M2, Covariance
from diffsense.sensors._mount import (
    MOUNT_DOMAINS,
    MOUNT_NAMES,
    Mount,
    Mounting,
    relevance_stand_ins,
)
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
from diffsense.sensors._weather import (
    CLEAR,
    KOSCHMIEDER_CONSTANT,
    KOSCHMIEDER_THRESHOLD,
    RADAR_FREQUENCY_GHZ,
    Weather,
    apparent_contrast,
    camera_extinction_1pm,
    contrast_range_m,
    contrast_transmission,
    fog_extinction_1pm,
    rain_coefficients,
    rain_extinction_1pm,
    rain_specific_attenuation_db_per_km,
    rain_two_way_loss_db,
    visibility_m,
)

__all__ = [
    # sensors, the suite and the registry
    "Camera", "Radar", "Sensor", "Suite", "fuse_members", "make_sensor", "register", "sensor_names",
    # constants, parameters and their domains
    "CameraConfig", "CameraParams", "CameraTemperatures", "MODES", "MOUNT_DOMAINS", "MOUNT_NAMES", "Mount", "Mounting",
    "ParamSpec",
    "RadarConfig", "RadarParams", "RadarTemperatures", "SENSORS", "check_params", "load_config",
    "make_params", "param_specs", "relevance_stand_ins", "resolve_name", "resolve_params", "with_param",
    # what a sensor reports, and the measurement covariance fusion takes
    "VARIANCE_FLOOR_M2", "Covariance", "Detections", "detect", "detect_batch", "measurement_noise", "p_detect",
    # radar and camera physics
    "camera_accuracy_px_per_rad", "camera_depth_sigma_m", "camera_detect", "camera_p_detect", "camera_px_per_rad",
    "radar_detect", "radar_gain_dbi", "radar_p_detect", "radar_rcs_dbsm", "radar_snr_db",
    "boresight_report", "coverage_field", "probe_scene",
    # the probabilistic detection laws
    "CameraDetection", "RadarDetection", "confidence_mean", "gaussian_beam_loss_db", "in_fov_fraction",
    "log_confidence_above", "log_reported_below", "swerling1_log_pd",
    # weather: ITU-R P.838-3 rain for the radar, Koschmieder contrast for the camera
    "CLEAR", "KOSCHMIEDER_CONSTANT", "KOSCHMIEDER_THRESHOLD", "RADAR_FREQUENCY_GHZ", "Weather",
    "apparent_contrast", "camera_extinction_1pm", "contrast_range_m", "contrast_transmission",
    "fog_extinction_1pm", "rain_coefficients", "rain_extinction_1pm", "rain_specific_attenuation_db_per_km",
    "rain_two_way_loss_db", "visibility_m",
]
