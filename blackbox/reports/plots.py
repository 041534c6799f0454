"""The one entry to matplotlib for every report.

Plots need the optional ``matplotlib`` (``pip install 'blackbox-joints[plots]'``); without it the
reports say so and the JSON/Markdown outputs are still written.
"""

from __future__ import annotations

__all__ = ["pyplot", "MAX_COLUMNS"]

MAX_COLUMNS = 60
"""A per-case or per-DOF picture with more columns than this is summarised instead (RMS per case,
largest DOFs), so a plot stays readable and of bounded size whatever the data's size."""


def pyplot():
    """matplotlib's pyplot on the non-interactive Agg backend, or None when it is not installed."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        return plt
    except ImportError:
        return None
