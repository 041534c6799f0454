"""The Pillow plots of ``identify`` (blackbox/reports/raster.py): data land where the axes say,
and identify draws its plots without importing matplotlib (what made its fixed cost)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

PIL = pytest.importorskip("PIL.Image")

from blackbox.reports import raster  # noqa: E402

from conftest import FIXTURES  # noqa: E402


def test_points_land_at_their_data_coordinates(tmp_path):
    fig = raster.Figure(400, 300)
    ax = fig.add_axes(50, 20, 350, 260)
    ax.limits([0.0, 10.0], [1.0, 1000.0], ylog=True, pad=0.0)
    ax.points([5.0], [10.0], color="#ff0000", size=3)
    fig.save(tmp_path / "p.png")
    img = np.asarray(PIL.open(tmp_path / "p.png").convert("RGB"))
    # x = 5 is the middle of 50..350; y = 10 is one third of the way up three decades
    col, row = 200, round(260 - (260 - 20) / 3)
    assert tuple(img[row, col]) == (255, 0, 0)
    assert tuple(img[row, col + 10]) == (255, 255, 255)


def test_diverging_scale_ends_and_nan():
    rgb = raster.diverging(np.array([-5.0, 0.0, 5.0, np.nan]), 5.0)
    assert rgb[0, 2] > rgb[0, 0] and rgb[2, 0] > rgb[2, 2]      # blue below, red above
    assert tuple(rgb[1]) == (247, 247, 247) and tuple(rgb[3]) == (200, 200, 200)


def test_identify_draws_its_plots_without_matplotlib(tmp_path):
    out = tmp_path / "id"
    code = ("import sys; from blackbox.cli import main; rc = main(['identify', sys.argv[1], '--out', "
            "sys.argv[2], '--no-cache']); print('matplotlib' in sys.modules); sys.exit(rc)")
    run = subprocess.run([sys.executable, "-c", code, str(FIXTURES / "cube"), str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().splitlines()[-1] == "False"
    for name in ("convergence.png", "estimates.png", "residuals.png"):
        with PIL.open(out / name) as im:
            assert im.format == "PNG" and im.width >= 400 and im.height >= 300
        assert f"]({name})" in (out / "report.md").read_text()
