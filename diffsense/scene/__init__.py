"""Scene engine: roads, vehicles, IDM/MOBIL traffic and the paper's lane-change scenarios.

    cfg = load_scenario("sc01")                                  # configs/scenarios/sc01.toml
    scene = simulate_scenario(cfg, 32, jax.random.key(0))        # Scene [32, 201, 5], variant 0 nominal
    kept = relevant_vehicles(scene, history_s=3.0, grid_half_length_m=29.7, sensor_reach_m=4.2)
"""

from diffsense.scene._datatypes import (
    ADJACENT,
    BACKGROUND,
    CAR,
    EGO,
    EGO_INDEX,
    KIND_NAMES,
    LEAD,
    ROLE_NAMES,
    TARGET,
    TARGET_INDEX,
    TARGET_LEAD,
    TRUCK,
    VAN,
    Scene,
)
from diffsense.scene._highd import load_highd
from diffsense.scene._idm import (
    FREE_ROAD_GAP_M,
    IDMParams,
    equilibrium_gap_m,
    idm_acceleration,
)
from diffsense.scene._lane_change import (
    quintic_lateral_offset_m,
    quintic_lateral_speed_mps,
    quintic_progress,
)
from diffsense.scene._load_recorded import load_recorded
from diffsense.scene._mobil import (
    MOBILParams,
    mobil_incentive_mps2,
    mobil_is_safe,
    mobil_wants_change,
)
from diffsense.scene._ngsim import load_ngsim
from diffsense.scene._relevant import (
    relevant_mask,
    relevant_selection,
    relevant_vehicles,
    select_vehicles,
)
from diffsense.scene._road import (
    Road,
    RoadConfig,
    cartesian_to_frenet,
    centreline_xy,
    curvature_1pm,
    frenet_to_cartesian,
    lane_centre_d_m,
    lane_index,
    list_roads,
    load_road,
    load_road_config,
    make_road,
    road_angle_rad,
)
from diffsense.scene._view import scene_figure, scene_json
from diffsense.scene._scenario_config import (
    check_speed_offset,
    ScenarioConfig,
    VehicleModels,
    list_scenarios,
    load_scenario,
    load_vehicle_models,
)
from diffsense.scene._simulate import SCENE_DT_S, simulate_scenario
from diffsense.scene._traffic import simulate_traffic
from diffsense.scene._traffic_config import TrafficConfig
from diffsense.scene._traffic_state import TrafficTrajectories

__all__ = [
    "ADJACENT", "BACKGROUND", "CAR", "EGO", "EGO_INDEX", "KIND_NAMES", "LEAD", "ROLE_NAMES",
    "TARGET", "TARGET_INDEX", "TARGET_LEAD", "TRUCK", "VAN", "Scene",
    "FREE_ROAD_GAP_M", "IDMParams", "equilibrium_gap_m", "idm_acceleration",
    "quintic_lateral_offset_m", "quintic_lateral_speed_mps", "quintic_progress",
    "MOBILParams", "mobil_incentive_mps2", "mobil_is_safe", "mobil_wants_change",
    "relevant_mask", "relevant_selection", "relevant_vehicles", "select_vehicles",
    "Road", "RoadConfig", "cartesian_to_frenet", "centreline_xy", "curvature_1pm",
    "frenet_to_cartesian", "lane_centre_d_m", "lane_index", "list_roads", "load_road",
    "load_road_config", "make_road", "road_angle_rad",
    "ScenarioConfig", "VehicleModels", "check_speed_offset", "scene_figure", "scene_json", "list_scenarios", "load_scenario", "load_vehicle_models",
    "SCENE_DT_S", "simulate_scenario",
    "TrafficConfig", "TrafficTrajectories", "simulate_traffic",
    "load_highd", "load_ngsim", "load_recorded",
]
