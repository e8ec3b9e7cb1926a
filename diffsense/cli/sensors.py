"""Sensor inspector: what a setting means for a vehicle on boresight, and its coverage field.

    python -m diffsense.sensors inspect --sensor radar --hfov 30 [--at-range 100] [--json]
    python -m diffsense.sensors inspect --sensor camera --hfov 30,90,180 --plot coverage.png

Bad input prints one line and exits with code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from diffsense.cli import run, setup_jax
from diffsense.runtime import InputError

_KINDS = ("car", "van", "truck")
_PLOT_FORMATS = ("png", "pdf", "svg")
_COLUMNS = {
    "radar": ("hfov_deg", "gain_dbi", "snr_db", "snr_range_m", "effective_range_m",
              "p_detect_soft", "p_detect_hard"),
    "camera": ("hfov_deg", "px_per_rad", "width_px_at_range", "depth_sigma_m",
               "resolvable_range_m", "effective_range_m", "p_detect_soft", "p_detect_hard"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line and exit 2 through run(), never usage + traceback
        raise InputError(message)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m diffsense.sensors", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p = sub.add_parser("inspect", help="link budget / coverage of sensor settings")
    p.add_argument("--sensor", required=True, choices=("radar", "camera"))
    p.add_argument("--config", help="TOML of sensor constants (any subset) replacing the profile's")
    p.add_argument("--profile", choices=("physical", "paper"), default="physical",
                   help="the shipped constants: physical (default) or paper (the paper's design)")
    p.add_argument("--hfov", help="HFOV [deg], or a comma-separated list (default: the config's)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="another parameter value, e.g. range_m=150 (repeatable)")
    p.add_argument("--at-range", type=float, help="range from the sensor [m] (default: range_m)")
    p.add_argument("--kind", choices=_KINDS, default="car", help="probe vehicle kind")
    p.add_argument("--length", type=float, default=4.5, help="probe vehicle length [m]")
    p.add_argument("--width", type=float, default=1.8, help="probe vehicle width [m]")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--plot", help="write the detection-probability field (png/pdf/svg)")
    return parser


def _floats(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{what}: expected numbers separated by commas, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"{what}: expected finite numbers, got {text!r}")
    return values


def _settings(args, config):
    from diffsense.sensors import make_params

    overrides: dict[str, float] = {}
    for item in args.set:
        name, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--set expects NAME=VALUE, got {item!r}")
        overrides[name.strip()] = _floats(value, f"--set {name.strip()}")[0]
    hfovs = _floats(args.hfov, "--hfov") if args.hfov else [config.params.hfov_deg]
    return [make_params(config, **overrides, hfov_deg=h) for h in hfovs]


def _check_probe(args) -> None:
    for name in ("length", "width"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"--{name} must be a positive number of metres, got {value:g}")
    if args.at_range is not None and not (math.isfinite(args.at_range) and args.at_range > 0):
        raise InputError(f"--at-range must be a positive number of metres, got {args.at_range:g}")
    if args.plot:
        suffix = args.plot.rsplit(".", 1)[-1].lower() if "." in args.plot else ""
        if suffix not in _PLOT_FORMATS:
            raise InputError(f"--plot {args.plot!r}: expected a .png, .pdf or .svg file name")


def _table(sensor: str, rows: list[dict]) -> str:
    cols = _COLUMNS[sensor]
    lines = ["  ".join(f"{c:>18}" for c in cols)]
    lines += ["  ".join(f"{row[c]:>18.4g}" for c in cols) for row in rows]
    return "\n".join(lines)


def _plot(path: str, sensor: str, settings, config, probe: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from diffsense.runtime import save_figure
    from diffsense.sensors import coverage_field

    reach = 1.2 * max(float(p.range_m) for p in settings)
    xs = np.linspace(-0.5 * reach, reach, 241)
    ys = np.linspace(-0.75 * reach, 0.75 * reach, 181)
    fig, axes = plt.subplots(1, len(settings), figsize=(4.2 * len(settings), 4.0), squeeze=False)
    for ax, params in zip(axes[0], settings):
        field = coverage_field(params, config, xs, ys, **probe)
        im = ax.imshow(field, origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]),
                       vmin=0.0, vmax=1.0, cmap="viridis", aspect="equal")
        ax.add_patch(plt.Rectangle((-2.25, -0.9), 4.5, 1.8, color="red"))
        ax.set_title(f"{sensor} HFOV {float(params.hfov_deg):g} deg")
        ax.set_xlabel("forward x [m]")
    axes[0][0].set_ylabel("left y [m]")
    fig.colorbar(im, ax=axes[0].tolist(), label="p_detect (soft)", shrink=0.8)
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    _check_probe(args)
    setup_jax(float64=True)
    from diffsense.sensors import load_config
    from diffsense.sensors import boresight_report

    config = load_config(args.sensor, args.config, args.profile)
    settings = _settings(args, config)
    probe = dict(kind=_KINDS.index(args.kind), length_m=args.length, width_m=args.width)
    rows = []
    for params in settings:
        at_range = float(params.range_m) if args.at_range is None else args.at_range
        rows.append(boresight_report(params, config, at_range, **probe))
    if args.plot:
        _plot(args.plot, args.sensor, settings, config, probe)
    if args.json:
        print(json.dumps({"sensor": args.sensor, "kind": args.kind, "results": rows}, indent=2))
    else:
        print(f"{args.sensor}, {args.kind} on boresight at {rows[0]['at_range_m']:g} m from the sensor")
        print(_table(args.sensor, rows))
        if args.plot:
            print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    run(lambda: main(sys.argv[1:]))
