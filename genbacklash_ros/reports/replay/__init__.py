"""The HTML report of a replay: PNG plots (matplotlib, Agg) and an ``index.html``.

What a drivetrain engineer looks at, from the :class:`~genbacklash_ros.bags.replay.ReplayResult`
(its history of estimates, commands and encoder readings) and, for a synthetic bag, the truth
its metadata carries (:func:`genbacklash_ros.bags.simbags.read_truth`). :func:`write_report`
writes into a directory

* ``motion.png``: the load position (encoder) against the command over the whole record --
  per pixel column the band between the smallest and largest value, so that commands that
  change every sample stay readable -- and a zoomed window (a few seconds with reversals,
  late in the record) where every command and reading is drawn;
* ``tracking_error.png``: the predicted load tracking error (load minus the command, taken as
  the desired load position) without compensation, with the compensation the node sent
  (running estimate, gated by confidence) and with the final estimate's inverse, as an RMS
  over time and in the zoomed window. The plant is the true drivetrain when the bag holds
  it, else the final estimate (then the numbers are the model's own prediction); the
  measured error (encoder minus command) is drawn as a check;
* ``play.png``: the play ``c_L + c_R`` and each dead zone over data time with +/-2 sigma
  from the published estimates' covariance, and the truth when the bag has it;
* ``coverage.png``: which part of the command range each branch was engaged over (time spent
  on each branch per command bin, classified with the final estimate), and the branches
  around the 1:1 line with the engaged parts drawn bold: what the data taught;
* ``characteristic.png``: the final estimate's branches with the aligned samples, as
  position and as the play around the 1:1 line (truth dashed);
* ``convergence.png``: every parameter over data time with a +/-2 sigma band (truth dashed);
* ``residuals.png``: encoder minus the final model's free-run simulation, and its histogram;
* ``compensation.png``: raw and compensated command in the zoomed window;
* ``index.html``: the tracking-error numbers, the final parameters (with the truth), the
  branch coverage, the replay's counters and the plots with captions.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # before any of the modules below imports pyplot

from .compensation import (
    compensation_section,
    compensation_spans,
    plot_compensation,
    plot_compensation_state,
)
from .coverage import Coverage, branch_coverage, coverage_text, plot_coverage
from .data import ReportData, report_data
from .figures import (
    plot_characteristic_report,
    plot_convergence,
    plot_gap,
    plot_motion,
    plot_residuals,
)
from .page import write_report
from .tracking import (
    TrackingErrors,
    plant_caption,
    plot_tracking_error,
    tracking_errors,
    tracking_headline,
    tracking_section,
)

__all__ = [
    "Coverage",
    "ReportData",
    "TrackingErrors",
    "branch_coverage",
    "compensation_section",
    "compensation_spans",
    "coverage_text",
    "plant_caption",
    "plot_characteristic_report",
    "plot_compensation",
    "plot_compensation_state",
    "plot_convergence",
    "plot_coverage",
    "plot_gap",
    "plot_motion",
    "plot_residuals",
    "plot_tracking_error",
    "report_data",
    "tracking_errors",
    "tracking_headline",
    "tracking_section",
    "write_report",
]
