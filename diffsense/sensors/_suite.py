"""Radar and camera as `Sensor`s: the physics of `_radar.py` and `_camera.py` behind the protocol."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import equinox as eqx

from diffsense.scene import Scene
from diffsense.sensors._camera import camera_detect
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import Mode
from diffsense.sensors._measure import KeyOrNoise
from diffsense.sensors._config import CameraConfig, RadarConfig, load_config, param_specs
from diffsense.sensors._params import CameraParams, ParamSpec, RadarParams
from diffsense.sensors._radar import radar_detect
from diffsense.sensors._sensor import Sensor, params_of, register


class Radar(Sensor):
    """The 77 GHz radar: SNR from the radar equation, gain tied to the beam, soft gates.

    `config` holds every constant (`configs/sensors/radar.toml`, or a user TOML via
    `Radar.from_toml`); its `params` are the defaults of r.
    """

    config: RadarConfig = eqx.field(static=True)
    kind: ClassVar[str] = "radar"

    @classmethod
    def from_toml(cls, path: str | Path | None = None, profile: str = "physical") -> Radar:
        """The radar of the shipped `profile` ("physical" or "paper"), with the keys of the TOML
        at `path` (any subset of its constants) replacing the profile's."""
        return cls(load_config("radar", path, profile))

    def param_specs(self) -> tuple[ParamSpec, ...]:
        return param_specs("radar", self.config)

    @property
    def mount_x_m(self) -> float:
        return float(self.config.mount_x_m)

    def _detect(self, scene: Scene, r: dict[str, Any], noise: KeyOrNoise, mode: Mode, temperature, weather) -> Detections:
        return radar_detect(scene, params_of(RadarParams, r), self.config, noise, mode=mode, temperature=temperature,
                            weather=weather)


class Camera(Sensor):
    """The stereo camera: equidistant lens, resolvability, stereo depth noise, occlusion.

    `config` holds every constant (`configs/sensors/camera.toml`, or a user TOML via
    `Camera.from_toml`); its `params` are the defaults of r.
    """

    config: CameraConfig = eqx.field(static=True)
    kind: ClassVar[str] = "camera"

    @classmethod
    def from_toml(cls, path: str | Path | None = None, profile: str = "physical") -> Camera:
        """The camera of the shipped `profile` ("physical" or "paper"), with the keys of the TOML
        at `path` (any subset of its constants) replacing the profile's."""
        return cls(load_config("camera", path, profile))

    def param_specs(self) -> tuple[ParamSpec, ...]:
        return param_specs("camera", self.config)

    @property
    def mount_x_m(self) -> float:
        return float(self.config.mount_x_m)

    def _detect(self, scene: Scene, r: dict[str, Any], noise: KeyOrNoise, mode: Mode, temperature, weather) -> Detections:
        return camera_detect(scene, params_of(CameraParams, r), self.config, noise, mode=mode, temperature=temperature,
                             weather=weather)


register("radar", Radar.from_toml)
register("camera", Camera.from_toml)
