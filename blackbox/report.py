"""Report helpers kept at their earlier import path; the reports live in :mod:`blackbox.reports`."""

from blackbox.reports.identify import fit_report, identification_plots  # noqa: F401
from blackbox.reports.plots import pyplot  # noqa: F401
