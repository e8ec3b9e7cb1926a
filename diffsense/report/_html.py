"""report.html: a run as one self-contained page, built from its result.json content.

The page needs no network: the CSS is inline, the run's PNG figures are embedded as base64 data
URLs and the sweep's chart (E with its interval per step, r* with its own) is inline SVG. Every
number the answer and the tables show is an element with `data-key` (where it sits in result.json,
dotted: "E", "E_ci.lo", "r_star.hfov_deg", "sweep.2.E_ci.hi", "judged.E_ref") and `data-value`
(the number as result.json holds it, full precision), so the page can be checked against the
file. A key result.json lacks (an older or a many-parameter run) leaves its part out.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from diffsense.solve import explain

FIGURES = {"objective.png": "E over the parameter: the soft and hard objectives, the sweep and r*",
           "rmse_horizon.png": "RMSE against the true future per sweep step",
           "detections.png": "hard detections of the first scenario's nominal variant"}
_CSS = """body{font:15px/1.45 system-ui,sans-serif;margin:2em auto;max-width:70em;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.8em}
table{border-collapse:collapse;margin:.5em 0}td,th{padding:.2em .7em;border-bottom:1px solid #eee;text-align:right}
td:first-child,th:first-child,td.text{text-align:left}.answer td{font-size:1.1em}
.best{font-weight:bold}.muted{color:#777}img{max-width:100%}figure{margin:1em 0}
.warn{color:#a40}code{font-size:.9em}"""


def _e(text: Any) -> str:
    return html.escape(str(text), quote=True)


def _finite(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _num(value: Any, key: str, spec: str = ".4f") -> str:
    """A number as shown, tagged with its result.json key and exact value; "-" where it is null."""
    if not _finite(value):
        return f'<span data-key="{_e(key)}" data-value="null">-</span>'
    return f'<span data-key="{_e(key)}" data-value="{float(value)!r}">{float(value):{spec}}</span>'


def _ci(ci: Sequence[float] | None, key: str, spec: str = ".4f") -> str:
    if not ci:
        return '<span class="muted">-</span>'
    return f"[{_num(ci[0], key + '.lo', spec)}, {_num(ci[1], key + '.hi', spec)}]"


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]], cls: str = "") -> str:
    """An HTML table; the cells are markup already (escaped by their makers)."""
    head = "".join(f"<th>{_e(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _on_ref(content: Mapping[str, Any]) -> bool:
    return (content.get("reference") or {}).get("answer_on") == "E_ref"


def answer_value(content: Mapping[str, Any]) -> float | None:
    """The E the answer is chosen on: E_ref(r*) under a probabilistic law, E_hard(r*) otherwise
    (what result.json's "E_ci" is an interval on)."""
    return content["reference"]["E_ref_star"] if _on_ref(content) else content.get("E_hard_star")


def _answer(content: Mapping[str, Any]) -> str:
    units, level = content.get("units") or {}, content.get("ci_level")
    e_name = "E_ref(r*)" if _on_ref(content) else "E_hard(r*)"
    r_ci = content.get("r_star_ci") or {}
    rows = [[f"r* {_e(n)}", f"{_num(v, f'r_star.{n}', '.6g')} {_e(units.get(n, ''))}"
             + (f"; with other traffic {_ci(r_ci[n], f'r_star_ci.{n}', '.4g')}" if r_ci.get(n) else "")]
            for n, v in (content.get("r_star") or {}).items()]
    rows.append([_e(e_name), f"{_num(answer_value(content), 'E')} m"])
    if "E_ci" in content:
        label = f"{level:.0%} interval" if _finite(level) else "interval"
        note = _e((content.get("ci_method") or {}).get("note") or "none")
        rows.append([_e(label), f"{_ci(content['E_ci'], 'E_ci')} m" if content["E_ci"] else
                     f'<span class="muted">{note}</span>'])
    if _on_ref(content):
        ref = content["reference"]
        rows.append(["standard error of the draws", f"{_num(ref.get('E_ref_star_se'), 'reference.E_ref_star_se')} m"
                     f" ({_e(ref.get('draws'))} detection draws)"])
        rows.append(["E_hard(r*), detections at their median", f"{_num(content.get('E_hard_star'), 'E_hard_star')} m"])
    rows.append(["E_soft(r*)", f"{_num(content.get('E_soft_star'), 'E_soft_star')} m"])
    j = content.get("judged")
    if j:
        rows.append([f"judged on fresh data (seed {_e(j.get('seed'))}, {_e(j.get('variants'))} variants)",
                     f"{_num(j.get('E_ref'), 'judged.E_ref')} &plusmn; {_num(j.get('E_ref_se'), 'judged.E_ref_se')} m"])
    if "on_bound" in content:
        rows.append(["r* on a bound", "yes" if content["on_bound"] else "no"])
    out = [_table(["", ""], rows, "answer")]
    near = content.get("near_optimal") or {}
    unit = units.get(content.get("param"), "") if content.get("param") else ""
    out += [f'<p class="warn">warning: {_e(w)}</p>'
            for w in explain(content.get("flags") or [], near.get("intervals") or [], unit)]
    out += [f"<p>note: {_e(n)}</p>" for n in content.get("notes") or []]
    return "".join(out)


def _flat(value: Any, prefix: str = "") -> list[tuple[str, str]]:
    """A nested config as dotted keys and their JSON values."""
    if isinstance(value, Mapping) and value:
        return [kv for k, v in value.items() for kv in _flat(v, f"{prefix}.{k}" if prefix else str(k))]
    return [(prefix, json.dumps(value))]


def _problem(content: Mapping[str, Any]) -> str:
    units = content.get("units") or {}
    rows = [["sensor", _e(content.get("sensor", "-"))],
            ["scenarios", _e(", ".join(content.get("scenarios") or []) or "-")],
            ["flags", _e(", ".join(content.get("flags") or []) or "none")]]
    rows += [[f"bounds of {_e(n)}", f"[{_num(lo, f'params.{n}.lo', '.6g')}, {_num(hi, f'params.{n}.hi', '.6g')}]"
              f" {_e(units.get(n, ''))}"] for n, (lo, hi) in (content.get("params") or {}).items()]
    m = content.get("ci_method") or {}
    if m.get("method"):
        rows.append(["intervals", _e(f"{m['method']}, {m.get('resamples')} resamples, strata {m.get('strata')}, "
                                     f"seed {m.get('seed')}")])
    ev, wall = content.get("evaluations") or {}, content.get("wall_s") or {}
    if ev:
        rows.append(["evaluations", _e(", ".join(f"{k} {v}" for k, v in ev.items()))])
    if wall:
        rows.append(["wall time [s]", _e(", ".join(f"{k} {v:.3g}" if _finite(v) else f"{k} {v}"
                                                  for k, v in wall.items()))])
    config = _table(["key", "value"], [[_e(k), f'<code class="text">{_e(v)}</code>']
                                       for k, v in _flat(content.get("config") or {})])
    versions = _e(", ".join(f"{k} {v}" for k, v in (content.get("versions") or {}).items()))
    return (_table(["", ""], rows) + f"<details><summary>the problem as configured</summary>{config}</details>"
            + (f'<p class="muted">versions: {versions}</p>' if versions else ""))


def _sweep(content: Mapping[str, Any]) -> str:
    sweep = content.get("sweep") or []
    if not sweep:
        return ""
    unit = (content.get("units") or {}).get(content.get("param"), "")
    same = set((content.get("near_optimal") or {}).get("indistinguishable") or [])
    best = min(range(len(sweep)), key=lambda i: (not _finite(sweep[i].get("E_hard")), sweep[i].get("E_hard") or 0))
    level = content.get("ci_level")
    rows = []
    for i, p in enumerate(sweep):
        mark = "best step" if i == best else ("cannot be told from the best" if p["r"] in same else "")
        rows.append([_num(p["r"], f"sweep.{i}.r", ".5g"), _num(p.get("E_hard"), f"sweep.{i}.E"),
                     _ci(p.get("E_ci"), f"sweep.{i}.E_ci"), _num(p.get("E_soft"), f"sweep.{i}.E_soft"), _e(mark)])
    e = "E_ref [m]" if _on_ref(content) else "E_hard [m]"
    ci = f"{level:.0%} CI [m]" if _finite(level) else "CI [m]"
    return (_table([f"{content.get('param')} [{unit}]", e, ci, "E_soft [m]", ""], rows, "sweep")
            + _chart(content))


def _chart(content: Mapping[str, Any]) -> str:
    """Inline SVG: each sweep step's E with its interval as an error bar, r* and its E's interval in
    red, and r*'s own interval ("r_star_ci") as a band behind them."""
    pts = [(p["r"], p["E_hard"], p.get("E_ci")) for p in content["sweep"] if _finite(p.get("E_hard"))]
    star = (content.get("r_star") or {}).get(content.get("param"))
    if _finite(star) and _finite(answer_value(content)):
        pts.append((star, answer_value(content), content.get("E_ci")))
    if not pts:
        return ""
    w, h, left, right, top, bottom = 640, 300, 64, 16, 16, 44
    xs = [x for x, _, _ in pts] + list(content.get("interval") or [])
    ys = [y for _, y, _ in pts] + [v for _, _, ci in pts for v in (ci or []) if _finite(v)]
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    pad = (y1 - y0) * 0.08 or 1.0
    y0, y1 = y0 - pad, y1 + pad

    def sx(x: float) -> float:
        return left + (x - x0) / ((x1 - x0) or 1.0) * (w - left - right)

    def sy(y: float) -> float:
        return top + (y1 - y) / (y1 - y0) * (h - top - bottom)

    band = ((content.get("r_star_ci") or {}).get(content.get("param")) or []) if _finite(star) else []
    out, banded = [], len(band) == 2 and all(_finite(v) for v in band)
    if banded:  # r*'s interval, a band behind the points
        a, b = (min(max(v, x0), x1) for v in band)
        out.append(f'<rect class="r-star-ci" x="{sx(a):.1f}" y="{top}" width="{max(sx(b) - sx(a), 1.0):.1f}" '
                   f'height="{h - top - bottom}" fill="#c22" fill-opacity="0.12"/>')
    out += [f'<line x1="{left}" y1="{h - bottom}" x2="{w - right}" y2="{h - bottom}" stroke="#444"/>',
           f'<line x1="{left}" y1="{top}" x2="{left}" y2="{h - bottom}" stroke="#444"/>']
    for k in range(5):
        xv, yv = x0 + (x1 - x0) * k / 4, y0 + (y1 - y0) * k / 4
        out.append(f'<text x="{sx(xv):.1f}" y="{h - bottom + 16}" text-anchor="middle">{xv:.4g}</text>')
        out.append(f'<text x="{left - 6}" y="{sy(yv) + 4:.1f}" text-anchor="end">{yv:.4g}</text>')
    for i, (x, y, ci) in enumerate(pts):
        colour = "#c22" if i == len(pts) - 1 and _finite(star) else "#236"
        if ci and all(_finite(v) for v in ci):
            out.append(f'<line x1="{sx(x):.1f}" y1="{sy(ci[0]):.1f}" x2="{sx(x):.1f}" y2="{sy(ci[1]):.1f}" '
                       f'stroke="{colour}" stroke-width="2"/>')
        out.append(f'<circle cx="{sx(x):.1f}" cy="{sy(y):.1f}" r="4" fill="{colour}"/>')
    unit = (content.get("units") or {}).get(content.get("param"), "")
    out.append(f'<text x="{(left + w - right) / 2}" y="{h - 6}" text-anchor="middle">'
               f'{_e(content.get("param"))} [{_e(unit)}]; red: r*{" (band: its interval)" if banded else ""}</text>')
    out.append(f'<text x="14" y="{(top + h - bottom) / 2}" text-anchor="middle" '
               f'transform="rotate(-90 14 {(top + h - bottom) / 2})">E [m] with its interval</text>')
    return (f'<figure><svg viewBox="0 0 {w} {h}" width="{w}" height="{h}" '
            f'font-size="11" role="img" aria-label="E per sweep step with its interval">{"".join(out)}</svg>'
            "<figcaption>E of each sweep step with its interval, and r*</figcaption></figure>")


def _verdicts(content: Mapping[str, Any]) -> str:
    comps = content.get("comparisons") or []
    if not comps:
        return ""
    rows = [[_e(c.get("a")), _e(c.get("b")), _num(c.get("diff_m"), f"comparisons.{i}.diff_m"),
             _ci(c.get("ci"), f"comparisons.{i}.ci"), _ci(c.get("ci_unpaired"), f"comparisons.{i}.ci_unpaired"),
             f'<span class="text verdict">{_e(c.get("verdict"))}</span>'] for i, c in enumerate(comps)]
    return _table(["a", "b", "E(a) - E(b) [m]", "paired CI", "unpaired CI", "verdict"], rows)


def _breakdown(content: Mapping[str, Any]) -> str:
    of = content.get("breakdown_of") or "E_hard"
    rows = [[_e(name), _num(part.get(of), f"by_scenario.{name}.{of}"),
             *(f"{part['coverage'][k]:.0%}" for k in ("at_instant", "in_window", "throughout"))]
            for name, part in (content.get("by_scenario") or {}).items() if part.get("coverage")]
    c = content.get("coverage")
    if not c:
        return ""
    rows.append(["pooled", _num(content.get("E_pooled"), "E_pooled"),
                 *(f"{c[k]:.0%}" for k in ("at_instant", "in_window", "throughout"))])
    out = [_table(["at r*", f"{of} [m]", "seen at t", "in window", "throughout"], rows)]
    parts = [[_e(k), f"{v['share']:.0%}", _num(v.get(of), f"coverage.parts.{k}.{of}")]
             for k, v in (c.get("parts") or {}).items()]
    out.append(_table(["instants whose target is seen", "share", f"{of} [m]"], parts))
    t = content.get("tracked")
    if t:
        out.append(f"<p>tracked question: E over tracked instants {_num(t.get('E_tracked'), 'tracked.E_tracked')} m, "
                   f"missed share {t['missed_share']:.1%}, J {_num(t.get('J_m2'), 'tracked.J_m2')} m&sup2;</p>")
    return "".join(out)


def _box(content: Mapping[str, Any]) -> str:
    box = content.get("box")
    if not box:
        return ""
    rows = [[_e(n), _num(g, f"box.gradient.{n}", ".4g"), _e((box.get("on_bound") or {}).get(n) or "interior")]
            for n, g in (box.get("gradient") or {}).items()]
    costs = ", ".join(f"{_e(m)} {_num(c, f'box.cost_by_member.{m}', '.4g')}"
                      for m, c in (box.get("cost_by_member") or {}).items())
    return (f"<p>J = E + {_num(box.get('cost_weight'), 'box.cost_weight', 'g')} &times; cost: "
            f"J {_num(box.get('J_star'), 'box.J_star')}, cost {_num(box.get('cost'), 'box.cost', '.4g')}"
            f"{'; by member: ' + costs if costs else ''}</p>"
            + _table(["parameter", "dJ/dr at r*", ""], rows))


def _figures(figures: Mapping[str, bytes]) -> str:
    return "".join(f'<figure><img alt="{_e(FIGURES.get(n, n))}" src="data:image/png;base64,'
                   f'{base64.b64encode(data).decode("ascii")}"><figcaption>{_e(n)}: {_e(FIGURES.get(n, ""))}'
                   "</figcaption></figure>" for n, data in figures.items())


def html_report(content: Mapping[str, Any], figures: Mapping[str, bytes] | None = None) -> str:
    """report.html's text: the answer, the problem, the sweep with its intervals and chart, the
    paired verdicts, the figures (PNG bytes by file name), the breakdown and a box solve's gradient.

    Args:
        content: the result.json content (`diffsense.Result.to_json()` or a loaded result.json).
        figures: {file name: PNG bytes} to embed, in order.
    """
    title = f"{content.get('sensor', 'run')}: " + (f"r* over {content['param']}" if content.get("param")
                                                    else f"r* of {len(content.get('r_star') or {})} parameters")
    sections = [("The answer", _answer(content)), ("The problem", _problem(content)),
                ("The sweep", _sweep(content)), ("Paired verdicts", _verdicts(content)),
                ("The figures", _figures(figures or {})), ("What E at r* is made of", _breakdown(content)),
                ("What still matters", _box(content))]
    body = "".join(f"<section><h2>{_e(h)}</h2>{s}</section>" for h, s in sections if s)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{_e(title)}</title>'
            f'<meta name="viewport" content="width=device-width,initial-scale=1">'
            f"<style>{_CSS}</style></head><body><h1>{_e(title)}</h1>{body}</body></html>\n")
