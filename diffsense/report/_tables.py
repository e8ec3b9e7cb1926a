"""Plain-text tables: the run summary and the paper's radar-versus-camera comparison.

Both read result dicts (the result.json content, `result_dict`), so a table can be rebuilt
from a saved run. `scale` and `unit` convert r for display (e.g. 180/pi and "deg").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from diffsense.solve import explain


def format_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """Aligned text: first column left-aligned, the others right-aligned."""
    cells = [[str(h) for h in headers]] + [[_cell(v) for v in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]

    def line(row: list[str]) -> str:
        parts = [row[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(row[1:], widths[1:])]
        return "  ".join(parts).rstrip()

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(cells[0]), rule] + [line(r) for r in cells[1:]])


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4f}"
    return str(value)


def _r(value: float | None, scale: float) -> str:
    """r for display: converted, 5 significant digits."""
    return "-" if value is None else f"{value * scale:.5g}"


def _r_star(result: Mapping[str, Any]) -> float:
    """r* of a one-parameter result.json (a dict {param: value}, or a bare number)."""
    r = result["r_star"]
    return r[result["param"]] if isinstance(r, Mapping) else r


def summary_table(result: Mapping[str, Any], *, scale: float = 1.0, unit: str = "") -> str:
    """The printed summary of one run: the sweep, then the continuous answer.

    Args:
        result: a result dict (result.json content).
        scale: display factor for r (e.g. 180/pi for degrees).
        unit: display unit of r.
    """
    name = f"{result['param']} [{unit}]" if unit else result["param"]
    best = min(result["sweep"], key=lambda p: (p["E_hard"] is None, p["E_hard"]))
    with_ci = "E_ci" in result  # a result.json written before intervals has no column for them
    rows = [
        [f"step {_r(p['r'], scale)}", p["E_hard"]] + ([_ci(p.get("E_ci"))] if with_ci else [])
        + [p["E_soft"], "best step" if p is best else ""]
        for p in result["sweep"]
    ]
    where = "on bound" if result["on_bound"] else "interior"
    r_star = f"r* {_r(_r_star(result), scale)}"
    ref = result.get("reference") or {}
    on_ref = ref.get("answer_on") == "E_ref"
    rows.append([r_star, ref["E_ref_star"] if on_ref else result["E_hard_star"]]
                + ([_ci(result["E_ci"])] if with_ci else []) + [result["E_soft_star"], where])
    ev, wall = result["evaluations"], result["wall_s"]
    level = f"{result.get('ci_level', 0.9):.0%} CI [m]"
    lines = [
        f"{result['sensor']}: {name} over [{_r(result['interval'][0], scale)}, "
        f"{_r(result['interval'][1], scale)}]",
        format_table(["r", "E_ref [m]" if on_ref else "E_hard [m]"] + ([level] if with_ci else [])
                     + ["E_soft [m]", ""], rows),
        f"continuous solve: {ev['objective']} objective + {ev['gradient']} gradient evaluations; "
        f"wall {wall['compile']:.1f} s compile + {wall['run']:.1f} s run",
    ]
    if on_ref:
        lines.append(f"E_ref(r*) = {ref['E_ref_star']:.4f} +- {ref['E_ref_star_se']:.4f} m (standard error; "
                     f"{ref['draws']} detection draws; estimator {ref['estimator']}); "
                     f"E_hard(r*) = {result['E_hard_star']:.4f} m with each detection at its median")
    lines += judged_lines(result)
    lines += interval_lines(result)
    lines += [f"note: {n}" for n in result.get("notes", [])]
    held = " (r* is on a bound, held there for small changes)" if result.get("on_bound") else ""
    for theta, d in (result.get("sensitivity") or {}).items():
        lines += [f"dr*/d{theta}: " + ", ".join(f"{p} {v:+.4g}" if v is not None else f"{p} undefined"
                                                for p, v in d.items()) + held]
    near = result.get("near_optimal") or {}
    lines += [f"warning: {w}" for w in explain(result.get("flags", []), near.get("intervals", []), unit)]
    return "\n".join(lines)


def comparison_table(
    results: Mapping[str, Mapping[str, Any]], *, scale: float = 1.0, unit: str = ""
) -> str:
    """The paper's radar-versus-camera comparison: E_hard per step and the optimum per sensor,
    then the paired comparison of the answers (the first result's "comparisons" "of" "sensors")
    with its unpaired interval beside it.

    Args:
        results: sensor name -> result dict, all for the same parameter and steps.
        scale, unit: display of r.
    """
    sensors = list(results)
    if not sensors:
        raise ValueError("no results to compare")
    steps = [p["r"] for p in results[sensors[0]]["sweep"]]
    for s in sensors[1:]:
        if [p["r"] for p in results[s]["sweep"]] != steps:
            raise ValueError(f"sensor {s!r} was swept on other steps than {sensors[0]!r}")
    label = f"{results[sensors[0]]['param']} [{unit}]" if unit else results[sensors[0]]["param"]
    rows = [
        [f"E_hard at {_r(r, scale)}"] + [results[s]["sweep"][i]["E_hard"] for s in sensors]
        for i, r in enumerate(steps)
    ]
    rows.append(["r*"] + [_r(_r_star(results[s]), scale) for s in sensors])
    rows.append(["E_hard(r*) [m]"] + [results[s]["E_hard_star"] for s in sensors])
    rows.append(["E_soft(r*) [m]"] + [results[s]["E_soft_star"] for s in sensors])
    rows.append(["r* on bound"] + [results[s]["on_bound"] for s in sensors])
    winner = min(sensors, key=lambda s: results[s]["E_hard_star"])
    return "\n".join(
        [
            f"{' vs '.join(sensors)}: {label}, "
            "E_RMSE [m] between GT-input and sensor-input predictions",
            format_table([""] + sensors, rows),
            f"best: {winner} at r* = {_r(_r_star(results[winner]), scale)} "
            f"(E_hard = {_cell(results[winner]['E_hard_star'])} m)",
        ] + [f"paired, each at its r*: {c['verdict']}; unpaired interval {_ci(c['ci_unpaired'])}"
             for c in results[sensors[0]].get("comparisons", []) if c.get("of") == "sensors"]
    )


def breakdown_table(result: Mapping[str, Any]) -> str:
    """What E at r* is made of: per scenario and per coverage class, with the shares of instants
    whose target was detected at the instant, in the window and throughout it (E_ref's parts
    over its detection draws, with expected shares, where result.json's "breakdown_of" says so)."""
    of = result.get("breakdown_of") or "E_hard"
    c = result.get("coverage")
    if not c:
        return ""
    with_ci = any("E_ci" in part for part in (result.get("by_scenario") or {}).values())
    rows = []
    for name, part in (result.get("by_scenario") or {}).items():
        cov = part["coverage"]
        rows.append([name, part[of]] + ([_ci(part.get("E_ci"))] if with_ci else [])
                    + [cov["at_instant"], cov["in_window"], cov["throughout"]])
    pooled = result.get("E_pooled")
    rows.append(["pooled", result["E_hard_star"] if pooled is None else pooled]
                + ([_ci(result.get("E_ci"))] if with_ci else []) + [c["at_instant"], c["in_window"], c["throughout"]])
    parts = ", ".join(f"{k} {v['share']:.0%} of instants, E {_cell(v[of])} m"
                      + (f" {_ci(v['E_ci'])}" if v.get("E_ci") else "") for k, v in c["parts"].items())
    level = f"{result.get('ci_level', 0.9):.0%} CI [m]"
    lines = [format_table(["at r*", f"{of} [m]"] + ([level] if with_ci else [])
                          + ["seen at t", "in window", "throughout"], rows),
             f"by coverage: {parts}"]
    t = result.get("tracked")
    if t:
        lines.append(f"tracked question: E over tracked instants {_cell(t['E_tracked'])} m, "
                     f"missed share {t['missed_share']:.1%}, J {_cell(t['J_m2'])} m^2")
    return "\n".join(lines)


def judged_lines(result: Mapping[str, Any]) -> list[str]:
    """The answer judged on data it was not chosen on (result.json's "judged"), as one line."""
    j = result.get("judged")
    if not j:
        return []
    return [(f"judged on fresh data (seed {j['seed']}: other scene variants, noise and detection draws, "
             f"{j['variants']} variants per scenario): E_ref(r*) = {_cell(j['E_ref'])} +- {_cell(j['E_ref_se'])} m"
             + (f", {_ci(j['E_ci'])} from its scene sample" if j.get("E_ci") else ""))]


def _ci(ci: Sequence[float] | None) -> str:
    """An interval [lo, hi] [m] as a cell; "-" where there is none."""
    return "-" if ci is None else f"[{ci[0]:.2f}, {ci[1]:.2f}]"


def interval_lines(result: Mapping[str, Any]) -> list[str]:
    """The paired comparisons' verdicts as one line, or why there are no intervals."""
    method = result.get("ci_method") or {}
    if "E_ci" not in result:
        return []
    if result["E_ci"] is None:
        return [f"intervals: {method.get('note') or 'none'}"]
    verdicts = [c["verdict"] for c in result.get("comparisons") or [] if c.get("of", "sweep") == "sweep"]
    head = (f"verdicts ({result['ci_level']:.0%} intervals of paired differences, "
            f"{method.get('resamples')} bootstrap resamples of the scene variants): ")
    return ([head + "; ".join(verdicts)] if verdicts else []) + _r_star_lines(result)


def _r_star_lines(result: Mapping[str, Any]) -> list[str]:
    """How far r* would move with other traffic (result.json's "r_star_ci"), where it is known."""
    method = result.get("ci_method") or {}
    out = []
    for name, (lo, hi) in (result.get("r_star_ci") or {}).items():
        unit = (result.get("units") or {}).get(name, "")
        gap = method.get("r_star_resolution")
        out.append(f"r* with other traffic: {name} in [{lo:.4g}, {hi:.4g}] {unit} ({result['ci_level']:.0%}, "
                   f"re-picked among the {method.get('r_star_points')} points evaluated"
                   + (f", {gap:.3g} {unit} apart at most there)" if gap is not None else ")")
                   + ("; a lower bound, r* chosen on E_hard" if method.get("r_star_caveat") else ""))
    return out


def _r_ci(ci: Sequence[float] | None) -> str:
    """r*'s interval of one parameter as a cell (its own units); "-" where there is none."""
    return "-" if ci is None else f"[{ci[0]:.4g}, {ci[1]:.4g}]"


def _on_ref(result: Mapping[str, Any]) -> bool:
    return (result.get("reference") or {}).get("answer_on") == "E_ref"


def box_table(result: Mapping[str, Any]) -> str:
    """The printed summary of a many-parameter solve: r*, what still matters (dJ/dr) and bounds."""
    box, r_ci = result["box"], result.get("r_star_ci") or {}
    rows = [[name, value] + ([_r_ci(r_ci.get(name))] if r_ci else []) + [
             result["units"][name], box["gradient"][name], box["on_bound"][name] or "interior"]
            for name, value in result["r_star"].items()]
    head = ["parameter", "r*"] + ([f"r* with other traffic ({result['ci_level']:.0%})"] if r_ci else []) + [
        "unit", "dJ/dr at r*", ""]
    lines = [f"{result['sensor']}: {len(rows)} parameters, J = E + {box['cost_weight']:g} x cost",
             format_table(head, rows),
             f"E_hard(r*) {_cell(result['E_hard_star'])} m, E_soft {_cell(result['E_soft_star'])} m, "
             f"cost {_cell(box['cost'])}, J {_cell(box['J_star'])} ({box['source']}); "
             f"{box['counts'].get('soft', 0)} value-and-gradient + {box['counts'].get('hard', 0)} "
             f"{'reference' if _on_ref(result) else 'hard'} evaluations"]
    if _on_ref(result):
        ref = result["reference"]
        lines.append(f"J is judged on E_ref: E_ref(r*) {_cell(ref['E_ref_star'])} +- {_cell(ref['E_ref_star_se'])} m "
                     f"(standard error; {ref['draws']} detection draws; estimator {ref['estimator']}); "
                     f"E_hard(r*) has each detection at its median")
    if box.get("cost_by_member"):
        lines.append("cost by member: " + ", ".join(f"{n} {_cell(c)}" for n, c in box["cost_by_member"].items()))
    if result.get("E_ci"):
        lines.append(f"{result['ci_level']:.0%} interval on the answer's E from the scene sample: {_ci(result['E_ci'])} m")
    if r_ci:
        lines.append("r* with other traffic: each parameter re-picked along its axis through r*, the others held "
                     "there (conditional: read one parameter at a time, not as a joint region; docs/uncertainty.md)"
                     + ("; a lower bound, r* chosen on E_hard" if not _on_ref(result) else ""))
    lines += [c['verdict'] for c in result.get("comparisons") or []
              if c.get("of") == "default"]
    lines += judged_lines(result)
    lines += [f"note: {n}" for n in result.get("notes", [])]
    return "\n".join(lines)
