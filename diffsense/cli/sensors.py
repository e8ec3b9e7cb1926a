"""Sensor inspector: what a setting means for a vehicle on boresight, and its coverage field.

    diffsense inspect --sensor radar --hfov 30 [--at-range 100] [--json]
    diffsense inspect --sensor camera --hfov 30,90,180 --plot coverage.png
    python -m diffsense.sensors inspect ...                     # the same

Bad input prints one line and exits with code 2.
"""

from __future__ import annotations

import argparse
import json
import math

from diffsense.cli import Parser, setup_jax
from diffsense.runtime import InputError
from diffsense.sensors import boresight_report, load_config, make_params

PROG = "python -m diffsense.sensors"

_KINDS = ("car", "van", "truck")
_PLOT_FORMATS = ("png", "pdf", "svg")
_COLUMNS = {
    "radar": ("hfov_deg", "gain_dbi", "snr_db", "snr_range_m", "effective_range_m",
              "p_detect_soft", "p_detect_hard"),
    "camera": ("hfov_deg", "px_per_rad", "width_px_at_range", "depth_sigma_m",
               "resolvable_range_m", "effective_range_m", "p_detect_soft", "p_detect_hard"),
}


def _parser(prog: str) -> argparse.ArgumentParser:
    parser = Parser(prog=prog, description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    _inspect_flags(sub.add_parser("inspect", help="link budget / coverage of sensor settings"))
    return parser


def _inspect_flags(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
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
    return p


def _floats(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{what}: expected numbers separated by commas, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"{what}: expected finite numbers, got {text!r}")
    return values


def _settings(args, config):
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
    if rows and "range_pd50_m" in rows[0]:  # Swerling I: where Pd is 0.5 and 0.9, not one threshold
        cols = tuple(c for c in cols if c != "snr_range_m")
        cols = cols[:3] + ("range_pd90_m", "range_pd50_m") + cols[3:]
    lines = ["  ".join(f"{c:>18}" for c in cols)]
    lines += ["  ".join(f"{row[c]:>18.4g}" for c in cols) for row in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    """`python -m diffsense.sensors inspect ...`."""
    return _inspect(_parser(prog).parse_args(argv))


def inspect(argv: list[str] | None = None, prog: str = "diffsense inspect") -> int:
    """`diffsense inspect ...`: the same command without the word `inspect`."""
    parser = Parser(prog=prog, description=__doc__.split("\n")[0])
    return _inspect(_inspect_flags(parser).parse_args(argv))


def _inspect(args: argparse.Namespace) -> int:
    _check_probe(args)
    setup_jax(float64=True)
    config = load_config(args.sensor, args.config, args.profile)
    settings = _settings(args, config)
    probe = {"kind": _KINDS.index(args.kind), "length_m": args.length, "width_m": args.width}
    rows = []
    for params in settings:
        at_range = float(params.range_m) if args.at_range is None else args.at_range
        rows.append(boresight_report(params, config, at_range, **probe))
    if args.plot:
        from diffsense import report  # start-up: matplotlib's figures, only for a plot

        report.plot_coverage(args.plot, args.sensor, settings, config, probe)
    if args.json:
        print(json.dumps({"sensor": args.sensor, "kind": args.kind, "results": rows}, indent=2))
    else:
        print(f"{args.sensor}, {args.kind} on boresight at {rows[0]['at_range_m']:g} m from the sensor")
        print(_table(args.sensor, rows))
        if args.plot:
            print(f"wrote {args.plot}")
    return 0
