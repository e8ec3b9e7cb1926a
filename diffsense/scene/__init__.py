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
from diffsense.scene._highd import load_highd, read_highd
from diffsense.scene._idm import (
    FREE_ROAD_GAP_M,
    IDMParams,
    desired_gap_m,
    equilibrium_gap_m,
    idm_acceleration,
)
from diffsense.scene._lane_change import (
    quintic_lateral_offset_m,
    quintic_lateral_speed_mps,
    quintic_progress,
)
from diffsense.scene._load_recorded import cut_recorded, load_recorded
from diffsense.scene._mobil import (
    MOBILParams,
    mobil_incentive_mps2,
    mobil_is_safe,
    mobil_wants_change,
)
from diffsense.scene._ngsim import load_ngsim, read_ngsim
from diffsense.scene._recorded import check_window, lane_changes, recorded_scenes
from diffsense.scene._recorded_types import (
    DEFAULT_WINDOW_S,
    Dropped,
    RecordedCut,
    Recording,
    RecordingSummary,
    Track,
    WindowInfo,
)
from diffsense.scene._relevant import (
    MARGIN_M,
    relevant_mask,
    relevant_selection,
    relevant_vehicles,
    select_vehicles,
)
from diffsense.scene._road import (
    MAX_PIECES,
    Road,
    RoadConfig,
    SegmentConfig,
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
from diffsense.scene._scenario_config import (
    BackgroundSpec,
    DriverModel,
    EgoSpec,
    KindModel,
    LaneChangeModel,
    LaneChangeSpec,
    Range,
    ScenarioConfig,
    VehicleModels,
    VehicleSpec,
    WeatherSpec,
    check_speed_offset,
    list_scenarios,
    load_scenario,
    load_vehicle_models,
    slowest_start_kmh,
)
from diffsense.scene._simulate import SCENE_DT_S, simulate_plan, simulate_scenario
from diffsense.scene._traffic import simulate_traffic, traffic_step
from diffsense.scene._traffic_config import (
    KindConfig,
    LaneChangeConfig,
    RingRoadConfig,
    SamplingConfig,
    TrafficConfig,
    TrafficRanges,
)
from diffsense.scene._traffic_state import (
    TrafficState,
    TrafficTrajectories,
    TrafficVehicles,
    init_traffic,
    lateral_offset_m,
    num_steps,
)
from diffsense.scene._variants import NO_LANE_CHANGE_S, ScenarioNumbers, VehiclePlan, draw_plan, scenario_numbers
from diffsense.scene._view import ROLE_COLOURS, road_json, scene_figure, scene_json

__all__ = [
    # the scene, its kinds and roles
    "ADJACENT", "BACKGROUND", "CAR", "EGO", "EGO_INDEX", "KIND_NAMES", "LEAD", "ROLE_NAMES",
    "TARGET", "TARGET_INDEX", "TARGET_LEAD", "TRUCK", "VAN", "Scene",
    # driver models: IDM, MOBIL, the quintic lane change
    "FREE_ROAD_GAP_M", "IDMParams", "desired_gap_m", "equilibrium_gap_m", "idm_acceleration",
    "MOBILParams", "mobil_incentive_mps2", "mobil_is_safe", "mobil_wants_change",
    "quintic_lateral_offset_m", "quintic_lateral_speed_mps", "quintic_progress",
    # roads
    "MAX_PIECES", "Road", "RoadConfig", "SegmentConfig", "cartesian_to_frenet", "centreline_xy",
    "curvature_1pm", "frenet_to_cartesian", "lane_centre_d_m", "lane_index", "list_roads", "load_road",
    "load_road_config", "make_road", "road_angle_rad",
    # the paper's scenarios: configs, variants (a plan per variant) and their simulation
    "BackgroundSpec", "DriverModel", "EgoSpec", "KindModel", "LaneChangeModel", "LaneChangeSpec", "Range",
    "ScenarioConfig", "VehicleModels", "VehicleSpec", "WeatherSpec", "check_speed_offset", "list_scenarios",
    "load_scenario", "load_vehicle_models", "slowest_start_kmh",
    "NO_LANE_CHANGE_S", "SCENE_DT_S", "ScenarioNumbers", "VehiclePlan", "draw_plan", "scenario_numbers",
    "simulate_plan", "simulate_scenario",
    # the relevant set
    "MARGIN_M", "relevant_mask", "relevant_selection", "relevant_vehicles", "select_vehicles",
    # training traffic on a ring road
    "KindConfig", "LaneChangeConfig", "RingRoadConfig", "SamplingConfig", "TrafficConfig", "TrafficRanges",
    "TrafficState", "TrafficTrajectories", "TrafficVehicles", "init_traffic", "lateral_offset_m", "num_steps",
    "simulate_traffic", "traffic_step",
    # recorded traffic (highD, NGSIM)
    "DEFAULT_WINDOW_S", "Dropped", "RecordedCut", "Recording", "RecordingSummary", "Track", "WindowInfo",
    "check_window", "cut_recorded", "lane_changes", "load_highd", "load_ngsim", "load_recorded", "read_highd", "read_ngsim",
    "recorded_scenes",
    # the viewer
    "ROLE_COLOURS", "road_json", "scene_figure", "scene_json",
]
