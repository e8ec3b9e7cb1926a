"""Notebook 06's written conclusions against its own stored tables (fast: no kernel runs).

The notebook prints, per sensor, a table of re-solved optima (theta, value, soft r*, reported r*,
dr*/dtheta, on a bound, E_hard) and a check table (secant between neighbouring optima, the
tangents at both ends, the tangent's miss and the no-move miss). Every number the conclusions and
docs/odd.md quote is checked here against those tables, and every comparison they state
(a secant between its tangents, a tangent within 5 % of a secant, rain narrowing the beam) is
recomputed from the table, so a re-execution that changes an output fails until the prose says
what the new output shows.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests._notebook_text import printed, prose, says

NB06 = "06_odd_sensitivity"
DOCS = Path(__file__).resolve().parents[1] / "docs" / "odd.md"
OPTIMA = "   theta   value  r* soft"
CHECKS = "   theta   from     to     secant"


def _rows(text: str, header: str) -> list[list[str]]:
    """The whitespace-split rows under `header`, up to the next header or the end."""
    out = []
    for line in text[text.index(header):].splitlines()[1:]:
        cells = line.split()
        if not cells or cells[0] == "theta":
            break
        out.append(cells)
    return out


def _optima(marker: str) -> dict[tuple[str, float], dict]:
    rows = _rows(printed(NB06, marker), OPTIMA)
    return {(c[0], float(c[1])): dict(r_soft=float(c[2]), r_star=float(c[3]), slope=float(c[4]),
                                      bound=c[5] == "True", E_hard=float(c[6])) for c in rows}


def _checks(marker: str) -> dict[tuple[str, float, float], dict]:
    rows = _rows(printed(NB06, marker), CHECKS)
    return {(c[0], float(c[1]), float(c[2])): dict(secant=float(c[3]), lo=float(c[4]), hi=float(c[5]),
                                                   miss=float(c[6]), still=float(c[7])) for c in rows}


def _camera():
    return _optima("r* soft"), _checks("tangent miss")


def _radar():
    return _optima("radar rain_mm_h = 0:"), _checks("radar rain_mm_h = 0:")


def _between(c: dict) -> bool:
    return min(c["lo"], c["hi"]) <= c["secant"] <= max(c["lo"], c["hi"])


def test_camera_conclusions():
    words = prose(NB06, "## Conclusions")
    says(words, "41.835 deg on [20, 90]", "-0.1184, -0.05385 and +0.02026 deg per km/h",
         "(-0.078 and -0.006 deg per km/h)", "by 0.8-1.0 deg over 20 km/h", "(0.81 against 1.56 deg)",
         "(0.96 against 0.12 deg)", "(+7.0e-05 deg per m)", "(E_hard 46.4 m)", "-1.27 deg per m")
    optima, checks = _camera()
    clear = optima[("rain_mm_h", 0.0)]
    assert clear["r_soft"] == 41.835 and not clear["bound"]
    assert [optima[("traffic_speed_kmh", v)]["slope"] for v in (-20.0, 0.0, 20.0)] == [-0.1184, -0.05385, 0.02026]
    assert optima[("rain_mm_h", 100.0)]["r_soft"] == clear["r_soft"] and clear["slope"] == 0.0
    fog30, fog60 = optima[("fog_visibility_m", 30.0)], optima[("fog_visibility_m", 60.0)]
    assert fog30["bound"] and fog30["slope"] == 0.0 and fog30["r_star"] == 90.0 and round(fog30["E_hard"], 1) == 46.4
    assert fog60["slope"] == pytest.approx(7.043e-05) and fog60["r_soft"] == clear["r_soft"]
    down, up = checks[("traffic_speed_kmh", -20.0, 0.0)], checks[("traffic_speed_kmh", 0.0, 20.0)]
    assert (round(down["secant"], 3), round(up["secant"], 3)) == (-0.078, -0.006)
    assert _between(down) and _between(up)
    assert 0.8 <= abs(down["miss"]) <= 1.0 and 0.8 <= abs(up["miss"]) <= 1.0
    assert (abs(down["miss"]), abs(down["still"])) == pytest.approx((0.806, 1.562)) and abs(down["miss"]) < abs(down["still"])
    assert (abs(up["miss"]), abs(up["still"])) == pytest.approx((0.957, 0.120)) and abs(up["miss"]) > abs(up["still"])
    assert round(checks[("fog_visibility_m", 30.0, 60.0)]["secant"], 2) == -1.27


def test_radar_conclusions():
    words = prose(NB06, "## Conclusions")
    says(words, "Rain narrows the radar's best beam", "from 8.236 deg in clear weather to 6.247 deg at 50 mm/h",
         "5 deg, at 100 mm/h", "-0.03788 deg per mm/h", "(-0.03979) within 5 %", "the secant is -0.02493",
         "Faster traffic widens the radar's best beam", "+0.03326, +0.06768 and +0.03992 deg per km/h",
         "0 km/h (+0.053) lies between the tangents at its ends", "+20 km/h (+0.038) lies just below both",
         "by 0.396 and 0.585 deg, against 1.061 and 0.769 deg")
    optima, checks = _radar()
    rain = [optima[("rain_mm_h", v)]["r_soft"] for v in (0.0, 50.0, 100.0)]
    assert rain == [8.236, 6.247, 5.0] and rain[0] > rain[1] > rain[2]
    assert optima[("rain_mm_h", 50.0)]["slope"] == -0.03788 and optima[("rain_mm_h", 100.0)]["slope"] == 0.0
    first, second = checks[("rain_mm_h", 0.0, 50.0)], checks[("rain_mm_h", 50.0, 100.0)]
    assert first["secant"] == -0.03979 and abs(first["hi"] - first["secant"]) <= 0.05 * abs(first["secant"])
    assert second["secant"] == -0.02493 and abs(second["secant"]) < abs(first["secant"])
    speed = [optima[("traffic_speed_kmh", v)] for v in (-20.0, 0.0, 20.0)]
    assert [r["slope"] for r in speed] == [0.03326, 0.06768, 0.03992]
    assert speed[0]["r_soft"] < speed[1]["r_soft"] < speed[2]["r_soft"]
    down, up = checks[("traffic_speed_kmh", -20.0, 0.0)], checks[("traffic_speed_kmh", 0.0, 20.0)]
    assert (round(down["secant"], 3), round(up["secant"], 3)) == (0.053, 0.038)
    assert _between(down) and up["secant"] < min(up["lo"], up["hi"])
    assert (abs(down["miss"]), abs(up["miss"]), abs(down["still"]), abs(up["still"])) == (0.396, 0.585, 1.061, 0.769)


def test_docs_quote_the_stored_run():
    # docs/odd.md's tables repeat the notebook's: the soft optima and slopes it quotes are the printed ones.
    text = " ".join(DOCS.read_text().split())
    camera, _ = _camera()
    radar, _ = _radar()
    for theta, value, table in (("traffic_speed_kmh", -20.0, camera), ("traffic_speed_kmh", 20.0, camera),
                                ("rain_mm_h", 50.0, radar), ("traffic_speed_kmh", -20.0, radar),
                                ("traffic_speed_kmh", 20.0, radar)):
        row = table[(theta, value)]
        assert f"| {row['r_soft']:.3f} |" in text and f"{row['slope']:+.4g}".lstrip("+") in text, (theta, value)
    assert "8.236 deg in clear weather" in text and "41.835 deg in clear weather" in text
