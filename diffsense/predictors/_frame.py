"""The predictor's unit and axis boundary, the one place where SI meets the model frame.

Outside (the project): SI road frame, last axis (lon_m, lat_m) = (forward, left), metres.
Inside (the network, as trained on NGSIM): last axis (lateral positive to the RIGHT, longitudinal
forward), feet. The paper's pipeline fed metres to feet-trained weights and kept CarMaker's
left-positive lateral axis; both mistakes are impossible here because nothing else converts.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.tracks import M_PER_FT


def si_to_model(xy_m: Float[Array, "... 2"]) -> Float[Array, "... 2"]:
    """(lon_m forward, lat_m left) -> (lateral_ft right, longitudinal_ft forward)."""
    lon, lat = xy_m[..., 0], xy_m[..., 1]
    return jnp.stack([-lat / M_PER_FT, lon / M_PER_FT], axis=-1)


def model_to_si(xy_ft: Float[Array, "... 2"]) -> Float[Array, "... 2"]:
    """(lateral_ft right, longitudinal_ft forward) -> (lon_m forward, lat_m left)."""
    lat_right, lon = xy_ft[..., 0], xy_ft[..., 1]
    return jnp.stack([lon * M_PER_FT, -lat_right * M_PER_FT], axis=-1)
