"""Report: result.json, the PNG figures and the printed tables of an optimisation run.

    plot_objective                   objective.png: E_soft, E_hard, dE/dr over r, sweep, r*
    plot_rmse_horizon                rmse_horizon.png: the paper's Figs 6/7
    plot_detection_timeline          the paper's Figs 8/9: p_detect over time per vehicle
    summary_table, comparison_table  plain-text tables (run summary; radar vs camera)
    write_run                        result.json (schema: `diffsense.Result`) and the three figures
    write_pareto, pareto_table       pareto.json and pareto.png of `diffsense.pareto`; its printed table
    CompileClock                     wall time split into JAX compilation and the rest

Everything is written atomically (diffsense.runtime._io).
"""

from diffsense.report._figures import (
    plot_detection_timeline,
    plot_objective,
    plot_rmse_horizon,
)
from diffsense.report._pareto import (
    PARETO_FILES,
    pareto_table,
    plot_pareto,
    write_pareto,
)
from diffsense.report._run import RUN_FILES, write_run
from diffsense.report._tables import (
    box_table,
    breakdown_table,
    comparison_table,
    format_table,
    summary_table,
)
from diffsense.runtime import CompileClock

__all__ = [
    "CompileClock",
    "PARETO_FILES",
    "RUN_FILES",
    "write_run",
    "box_table",
    "breakdown_table",
    "comparison_table",
    "format_table",
    "plot_detection_timeline",
    "plot_objective",
    "plot_rmse_horizon",
    "summary_table",
    "pareto_table",
    "plot_pareto",
    "write_pareto",
]
