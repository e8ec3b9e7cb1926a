"""Report: result.json, the PNG figures and the printed tables of an optimisation run.

    plot_objective                   objective.png: E_soft, E_hard, dE/dr over r, sweep, r*
    plot_rmse_horizon                rmse_horizon.png: the paper's Figs 6/7
    plot_detection_timeline          the paper's Figs 8/9: p_detect over time per vehicle
    plot_coverage                    the sensor inspector's p_detect field around the sensor
    summary_table, comparison_table  plain-text tables (run summary; radar vs camera)
    write_run                        result.json (schema: `diffsense.Result`), the three figures, report.html
    html_report                      report.html: the run as one self-contained page (result.json's content)
    write_pareto, pareto_table       pareto.json and pareto.png of `diffsense.pareto`; its printed table
    print_case_study                 the case study's tables and statements (diffsense.report.case_study)
    CompileClock                     wall time split into JAX compilation and the rest

Everything is written atomically (`diffsense.runtime.atomic_open`).
"""

from diffsense.report._coverage import plot_coverage
from diffsense.report._figures import (
    plot_detection_timeline,
    plot_objective,
    plot_rmse_horizon,
)
from diffsense.report._html import html_report
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
from diffsense.report.case_study import print_case_study
from diffsense.runtime import CompileClock

__all__ = [
    "PARETO_FILES", "RUN_FILES", "CompileClock", "box_table", "breakdown_table", "comparison_table", "format_table",
    "html_report", "pareto_table", "plot_coverage", "plot_detection_timeline", "plot_objective", "plot_pareto", "plot_rmse_horizon",
    "print_case_study", "summary_table", "write_pareto", "write_run",
]
