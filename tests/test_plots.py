"""What the plots draw, read from the figures themselves just before they are saved: every bar of
diagnose's ``candidates.png`` inside its axis and as long as its value, every parameter in the
batch's ``summary.png`` (or the plot saying which are left out)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

matplotlib = pytest.importorskip("matplotlib")

import blackbox                                                  # noqa: E402
from blackbox.reports.batch import PLOT_PANELS, summary_plot      # noqa: E402

from conftest import FIXTURES                                    # noqa: E402


@pytest.fixture
def saved(monkeypatch):
    """The figures saved during the test, by file name, as they were when saved."""
    from matplotlib.figure import Figure

    figures = {}
    original = Figure.savefig

    def keep(self, fname, *args, **kwargs):
        figures[str(fname).rsplit("/", 1)[-1]] = self
        return original(self, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return figures


def test_candidate_bars_are_their_values_inside_the_axis(tmp_path, saved):
    """The candidates' -log10 p run to thousands on this study; capped at 300 every bar was
    drawn to the cap, off its axis's end. Now each bar is its candidate's value."""
    res = blackbox.diagnose(FIXTURES / "undeclared" / "support_flexibility")
    res.write(tmp_path)
    fig = saved["candidates.png"]
    ax = fig.axes[0]
    lo, hi = ax.get_xlim()
    widths = [p.get_width() for p in ax.patches]
    step = res.diagnosis.steps[0]
    want = [-c.log10_p for c in step.scores if c.df > 0][:len(widths)]
    assert widths == pytest.approx(want, rel=1e-12)
    assert max(widths) > 1000 and len(set(widths)) == len(widths)     # not one capped length
    assert all(lo < w < hi for w in widths)
    for t in ax.texts:                                                # the dBIC labels inside too
        assert lo < t.get_position()[0] < hi


def _outcomes(n_params: int, n_studies: int = 3):
    params = [{"joint": "J", "name": f"k{i:02d}", "value": 1e3 * (i + 1), "ci_low": 9e2 * (i + 1),
               "ci_high": 1.1e3 * (i + 1)} for i in range(n_params)]
    return [SimpleNamespace(name=f"s{s}", parameters=params, reduced_chi2=1.0 + 0.1 * s, status="ok", wall_s=0.1,
                            worker=None, message="") for s in range(n_studies)]


def test_the_batch_plot_shows_every_parameter(tmp_path, saved):
    """18 parameters (two simple joints of 3 branches) and the reduced chi2: 19 panels."""
    assert summary_plot(_outcomes(18), tmp_path / "summary.png")
    fig = saved["summary.png"]
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert titles == [f"J.k{i:02d}" for i in range(18)] + ["reduced chi2"]
    assert fig._suptitle is None


def test_the_batch_plot_says_what_it_leaves_out(tmp_path, saved):
    assert summary_plot(_outcomes(10), tmp_path / "summary.png", max_panels=6)     # a small figure
    fig = saved["summary.png"]
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 6 + 1
    assert "the first 6 of 10 parameters" in fig._suptitle.get_text()
    from blackbox.reports.batch import summary_markdown
    n = PLOT_PANELS + 12
    text = summary_markdown(SimpleNamespace(outcomes=_outcomes(n), counts=lambda: {"ok": 3}, sub_command="identify",
                                            executor="serial", wall_s=1.0), ["summary.png"])
    assert f"The plot shows the first {PLOT_PANELS} of the {n} parameters" in text
