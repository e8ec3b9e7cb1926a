"""Scene engine: roads, vehicles, IDM/MOBIL traffic and the paper's lane-change scenarios."""

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
from diffsense.scene._idm import FREE_ROAD_GAP_M, IDMParams, equilibrium_gap_m, idm_acceleration
from diffsense.scene._mobil import MOBILParams, mobil_incentive_mps2, mobil_is_safe, mobil_wants_change

__all__ = [
    "ADJACENT", "BACKGROUND", "CAR", "EGO", "EGO_INDEX", "KIND_NAMES", "LEAD", "ROLE_NAMES",
    "TARGET", "TARGET_INDEX", "TARGET_LEAD", "TRUCK", "VAN", "Scene",
    "FREE_ROAD_GAP_M", "IDMParams", "equilibrium_gap_m", "idm_acceleration",
    "MOBILParams", "mobil_incentive_mps2", "mobil_is_safe", "mobil_wants_change",
]
