"""A Pareto sweep's outputs: pareto.json, pareto.png (E against cost, the designs labelled by their
cost weight) and the printed table of the designs.

E is the hard objective's value (E_hard), or under a probabilistic detection law its expectation
over detection draws (E_ref): pareto.json's `judged_on` says which. The figure shows every point
the sweep evaluated on it (grey), the designs the sweep chose (one per cost weight lambda: filled
and joined when non-dominated, hollow when another design is both better and cheaper), each
labelled "lambda = ...".
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from diffsense.report._tables import format_table
from diffsense.runtime import save_figure, write_json

PARETO_FILES = ("pareto.json", "pareto.png")


def plot_pareto(path: str | Path, content: dict[str, Any], title: str) -> list[str]:
    """Draw pareto.png from pareto.json's `content`; returns the labels drawn, one per design."""
    fig = Figure(figsize=(7.5, 5.0))
    ax = fig.add_subplot()
    name = content.get("judged_on", "E_hard")
    key, cloud = f"{name}_m", content["cloud"]
    ax.scatter(cloud["cost"], cloud[key], s=8, color="0.75", label="evaluated (hard)", zorder=1)
    designs = content["designs"]
    front = content["front"]
    ax.plot([designs[i]["cost"] for i in front], [designs[i][key] for i in front], "-o", color="C0",
            zorder=3, label="front (non-dominated designs)")
    dominated = [d for d in designs if not d["on_front"]]
    if dominated:
        ax.scatter([d["cost"] for d in dominated], [d[key] for d in dominated], facecolors="none",
                   edgecolors="C3", zorder=3, label="dominated design")
    labels = []
    for k, d in enumerate(designs):
        text = f"lambda = {d['lambda']:g}"
        labels.append(text)
        # Alternate the offsets: neighbouring designs often sit close together.
        ax.annotate(text, (d["cost"], d[key]), xytext=(6, 6 if k % 2 == 0 else -12),
                    textcoords="offset points", fontsize=8)
    ax.set_xlabel(f"cost [{content['currency']}]")
    ax.set_ylabel(f"{name} [m]")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=120)
    return labels


def write_pareto(front: Any, folder: str | Path) -> dict[str, Any]:
    """Write pareto.json and pareto.png of a `ParetoFront` into `folder`; returns the JSON content."""
    folder = Path(folder)
    content = front.to_dict()
    write_json(folder / "pareto.json", content)
    plot_pareto(folder / "pareto.png", content, f"{front.sensor}: {front.judged_on} against cost, one design per lambda "
                f"[m per {front.currency}]")
    return content


def pareto_table(content: dict[str, Any]) -> str:
    """The printed designs: lambda, E (E_hard or E_ref), cost, whether on the front, and r* per parameter."""
    names = list(content["designs"][0]["r_star"]) if content["designs"] else []
    name = content.get("judged_on", "E_hard")
    rows = [[f"{d['lambda']:g}", d[f"{name}_m"], d["cost"], d["on_front"], *(d["r_star"][n] for n in names)]
            for d in content["designs"]]
    head = f"{content['sensor']}: E-versus-cost front, {len(content['designs'])} cost weights " \
           f"[m per {content['currency']}]; {content['evaluations']['soft']} value-and-gradient + " \
           f"{content['evaluations']['hard']} hard evaluations"
    return head + "\n" + format_table(["lambda", f"{name} [m]", f"cost [{content['currency']}]", "front",
                                       *(f"{n} [{content['units'][n]}]" for n in names)], rows)
