"""What a run leaves behind: its folder (time series, summary, plots), written atomically, and
the self-contained HTML report."""

from scenarios.output.plots import PLOTS, write_plots, write_sweep_plot
from scenarios.output.report import render_report, write_report
from scenarios.output.workbook import (psd_table, workbook_problem, write_size_csvs, write_sweep_workbook,
                                       write_workbook)
from scenarios.output.write import (INCOMPLETE_MARKER, MANIFEST, OutputClaim, claim_output, manifest_of,
                                    replace_recorded_files, strangers, write_files, write_run)

__all__ = ["INCOMPLETE_MARKER", "MANIFEST", "OutputClaim", "PLOTS", "claim_output", "manifest_of",
           "psd_table",
           "render_report", "replace_recorded_files", "strangers", "workbook_problem", "write_files", "write_plots", "write_report", "write_run",
           "write_size_csvs", "write_sweep_plot", "write_sweep_workbook", "write_workbook"]
