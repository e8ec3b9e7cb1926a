"""The sensor inspector's figure: the soft detection probability around the sensor, one panel per
setting (`diffsense inspect --plot FILE`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from diffsense.runtime import save_figure
from diffsense.sensors import coverage_field


def plot_coverage(path: str | Path, sensor: str, settings: Sequence[Any], config: Any, probe: dict[str, Any]) -> None:
    """Draw p_detect (soft) of a probe vehicle (`probe`: coverage_field's kind, length_m,
    width_m) over x in [-0.5, 1] x reach and y in [-0.75, 0.75] x reach [m], reach 1.2 x the
    longest range_m of `settings`; the sensor's own vehicle in red at the origin."""
    reach = 1.2 * max(float(p.range_m) for p in settings)
    xs = np.linspace(-0.5 * reach, reach, 241)
    ys = np.linspace(-0.75 * reach, 0.75 * reach, 181)
    fig = Figure(figsize=(4.2 * len(settings), 4.0))
    axes = fig.subplots(1, len(settings), squeeze=False)
    for ax, params in zip(axes[0], settings):
        field = coverage_field(params, config, xs, ys, **probe)
        im = ax.imshow(field, origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]),
                       vmin=0.0, vmax=1.0, cmap="viridis", aspect="equal")
        ax.add_patch(Rectangle((-2.25, -0.9), 4.5, 1.8, color="red"))
        ax.set_title(f"{sensor} HFOV {float(params.hfov_deg):g} deg")
        ax.set_xlabel("forward x [m]")
    axes[0][0].set_ylabel("left y [m]")
    fig.colorbar(im, ax=axes[0].tolist(), label="p_detect (soft)", shrink=0.8)
    save_figure(fig, path, dpi=120)
