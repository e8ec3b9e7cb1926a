"""Report: result.json, the PNG figures and the printed tables of an optimisation run.

    result_dict, write_result_json   the machine-readable record (schema: _result.py docstring)
    plot_objective                   objective.png: E_soft, E_hard, dE/dr over r, sweep, r*
    plot_rmse_horizon                rmse_horizon.png: the paper's Figs 6/7
    plot_detection_timeline          the paper's Figs 8/9: p_detect over time per vehicle
    summary_table, comparison_table  plain-text tables (run summary; radar vs camera)

Everything is written atomically (diffsense._io).
"""

from diffsense.report._figures import plot_detection_timeline, plot_objective, plot_rmse_horizon
from diffsense.report._result import RESULT_KEYS, result_dict, versions, write_result_json
from diffsense.report._tables import comparison_table, format_table, summary_table

__all__ = [
    "RESULT_KEYS",
    "comparison_table",
    "format_table",
    "plot_detection_timeline",
    "plot_objective",
    "plot_rmse_horizon",
    "result_dict",
    "summary_table",
    "versions",
    "write_result_json",
]
