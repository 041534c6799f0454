"""Small line, scatter, error-bar and map plots drawn straight into a PNG with Pillow.

``identify`` is the command users run most; drawing its four plots with matplotlib cost more CPU
than the rest of the command (importing pyplot and laying out text take about a second, the
fit a tenth of that). These plots need only axes, ticks, lines, markers and a colour map, so
they are drawn here in milliseconds. Pillow ships with matplotlib (the ``plots`` extra); without
it the reports say that no plots were drawn, as without matplotlib.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["available", "Figure", "Axes", "PALETTE", "diverging"]

PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
           "#bcbd22", "#17becf"]
"""Line colours in order (matplotlib's default cycle, so the plots look like the others)."""


def available() -> bool:
    """Whether Pillow is installed."""
    try:
        import PIL.Image  # noqa: F401
        return True
    except ImportError:
        return False


def _font(size: int):
    from PIL import ImageFont
    try:
        return ImageFont.load_default(size=size)      # a scalable font (Pillow >= 10.1 with FreeType)
    except TypeError:
        return ImageFont.load_default()


def diverging(v: np.ndarray, lim: float) -> np.ndarray:
    """RGB (uint8, ``v.shape + (3,)``) of ``v`` on a blue-white-red scale over ``[-lim, lim]``
    (blue negative); NaN grey."""
    t = np.clip(np.nan_to_num(np.asarray(v, float) / lim, nan=0.0), -1.0, 1.0)
    blue, red, white = np.array([33, 102, 172]), np.array([178, 24, 43]), np.array([247, 247, 247])
    a = np.abs(t)[..., None]
    rgb = np.where(t[..., None] < 0, white + a * (blue - white), white + a * (red - white))
    rgb = np.where(np.isnan(np.asarray(v, float))[..., None], 200.0, rgb)
    return rgb.astype(np.uint8)


def _nice_ticks(lo: float, hi: float, n: int = 6) -> list[float]:
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return [lo]
    raw = (hi - lo) / max(n - 1, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    first = math.ceil(lo / step - 1e-9) * step
    return [first + i * step for i in range(int((hi - first) / step + 1e-9) + 1)]


def _fmt(v: float) -> str:
    if v == 0:
        return "0"
    a = abs(v)
    if 1e-3 <= a < 1e5:
        return f"{v:.6g}"
    m, e = f"{v:.2e}".split("e")
    m = m.rstrip("0").rstrip(".")
    return f"{m}e{int(e)}"


class Axes:
    """One panel: data limits, a linear or log y (and x) scale, and drawing in data coordinates."""

    def __init__(self, fig: "Figure", box: tuple[int, int, int, int]):
        self.fig, self.box = fig, box            # pixel box of the plotting area (x0, y0, x1, y1)
        self.xlim = self.ylim = None
        self.xlog = self.ylog = False
        self.legend_items: list[tuple[str, str, str]] = []
        self._xticks: tuple[Sequence[float], Sequence[str], bool] | None = None
        self._yticks: tuple[Sequence[float], Sequence[str]] | None = None
        self.title = self.xlabel = self.ylabel = ""

    # ---- limits and coordinates ---------------------------------------------------------------
    def limits(self, x: np.ndarray, y: np.ndarray, *, xlog: bool = False, ylog: bool = False,
               pad: float = 0.05) -> None:
        """Data limits from the values drawn (finite ones; positive ones on a log scale)."""
        self.xlog, self.ylog = xlog, ylog
        self.xlim = self._span(np.asarray(x, float), xlog, pad)
        self.ylim = self._span(np.asarray(y, float), ylog, pad)

    @staticmethod
    def _span(v: np.ndarray, log: bool, pad: float) -> tuple[float, float]:
        v = v[np.isfinite(v) & ((v > 0) if log else True)]
        if not v.size:
            return (1.0, 10.0) if log else (0.0, 1.0)
        lo, hi = float(v.min()), float(v.max())
        if log:
            lo, hi = math.log10(lo), math.log10(hi)
        if hi - lo < 1e-12 * max(1.0, abs(hi)):
            lo, hi = lo - 0.5, hi + 0.5
        d = (hi - lo) * pad
        return lo - d, hi + d

    def _tx(self, x):
        x = np.asarray(x, float)
        v = np.log10(np.where(x > 0, x, np.nan)) if self.xlog else x
        x0, _, x1, _ = self.box
        return x0 + (v - self.xlim[0]) / (self.xlim[1] - self.xlim[0]) * (x1 - x0)

    def _ty(self, y):
        y = np.asarray(y, float)
        v = np.log10(np.where(y > 0, y, np.nan)) if self.ylog else y
        _, y0, _, y1 = self.box
        return y1 - (v - self.ylim[0]) / (self.ylim[1] - self.ylim[0]) * (y1 - y0)

    # ---- drawing --------------------------------------------------------------------------------
    def line(self, x, y, color: str = PALETTE[0], width: int = 2, label: str | None = None) -> None:
        px, py = self._tx(x), self._ty(y)
        ok = np.isfinite(px) & np.isfinite(py)
        pts = list(zip(px[ok].tolist(), py[ok].tolist()))
        if len(pts) >= 2:
            self.fig.draw.line(pts, fill=color, width=width)
        if label:
            self.legend_items.append(("line", color, label))

    def points(self, x, y, color: str = PALETTE[0], size: int = 3, marker: str = "o",
               label: str | None = None) -> None:
        d = self.fig.draw
        for a, b in zip(self._tx(x).tolist(), self._ty(y).tolist()):
            if not (math.isfinite(a) and math.isfinite(b)):
                continue
            if marker == "x":
                d.line([(a - size, b - size), (a + size, b + size)], fill=color, width=2)
                d.line([(a - size, b + size), (a + size, b - size)], fill=color, width=2)
            elif marker == "_":
                d.line([(a - 3 * size, b), (a + 3 * size, b)], fill=color, width=2)
            else:
                d.ellipse([a - size, b - size, a + size, b + size], fill=color)
        if label:
            self.legend_items.append((marker, color, label))

    def errorbars(self, x, lo, hi, color: str = PALETTE[0]) -> None:
        d = self.fig.draw
        for a, b, c in zip(self._tx(x).tolist(), self._ty(lo).tolist(), self._ty(hi).tolist()):
            if all(math.isfinite(v) for v in (a, b, c)):
                d.line([(a, b), (a, c)], fill=color, width=1)
                d.line([(a - 4, b), (a + 4, b)], fill=color, width=1)
                d.line([(a - 4, c), (a + 4, c)], fill=color, width=1)

    def hline(self, y: float, color: str = "#000000", width: int = 1) -> None:
        py = float(self._ty([y])[0])
        if math.isfinite(py):
            self.fig.draw.line([(self.box[0], py), (self.box[2], py)], fill=color, width=width)

    def vline(self, x: float, color: str = "#000000", width: int = 1) -> None:
        px = float(self._tx([x])[0])
        if math.isfinite(px):
            self.fig.draw.line([(px, self.box[1]), (px, self.box[3])], fill=color, width=width)

    def hspan(self, y0: float, y1: float, color: str = "#d9d9d9", label: str | None = None) -> None:
        a, b = sorted(float(v) for v in self._ty([y0, y1]))
        a, b = max(a, self.box[1]), min(b, self.box[3])
        if b > a:
            self.fig.draw.rectangle([self.box[0], a, self.box[2], b], fill=color)
        if label:
            self.legend_items.append(("box", color, label))

    def vspan(self, x0: float, x1: float, color: str = "#e6e6e6") -> None:
        a, b = sorted(float(v) for v in self._tx([x0, x1]))
        a, b = max(a, self.box[0]), min(b, self.box[2])
        if b > a:
            self.fig.draw.rectangle([a, self.box[1], b, self.box[3]], fill=color)

    def bars(self, x, h, color: str = PALETTE[0], width: float = 0.8) -> None:
        base = self._ty([self.ylim[0] if not self.ylog else 10 ** self.ylim[0]])[0]
        for a, b in zip(np.asarray(x, float), np.asarray(h, float)):
            l, r = self._tx([a - width / 2, a + width / 2])
            t = float(self._ty([b])[0])
            if math.isfinite(t):
                self.fig.draw.rectangle([l, min(t, base), r, max(t, base)], fill=color)

    def image(self, rgb: np.ndarray) -> None:
        """An RGB array filling the plotting area, row 0 at the top (a map of cells)."""
        from PIL import Image
        x0, y0, x1, y1 = self.box
        img = Image.fromarray(rgb, "RGB").resize((max(x1 - x0, 1), max(y1 - y0, 1)), Image.NEAREST)
        self.fig.img.paste(img, (x0, y0))

    def xticks(self, positions: Sequence[float], labels: Sequence[str], vertical: bool = False) -> None:
        self._xticks = (positions, labels, vertical)

    def yticks(self, positions: Sequence[float], labels: Sequence[str]) -> None:
        self._yticks = (positions, labels)

    # ---- frame, ticks, labels, legend (drawn last, over the data) -------------------------------
    def finish(self) -> None:
        f, d = self.fig, self.fig.draw
        x0, y0, x1, y1 = self.box
        d.rectangle([x0, y0, x1, y1], outline="#000000", width=1)
        small = f.font(11)
        if self._xticks is not None:
            pos, labels, vertical = self._xticks
        else:
            pos = self._auto(self.xlim, self.xlog)
            labels, vertical = [_fmt(p) for p in pos], False
        for p, lab in zip(self._tx(pos).tolist(), labels):
            if math.isfinite(p) and x0 - 0.5 <= p <= x1 + 0.5:
                d.line([(p, y1), (p, y1 + 4)], fill="#000000")
                f.text((p, y1 + 6), lab, small, anchor="rt" if vertical else "mt", vertical=vertical)
        if self._yticks is not None:
            pos, labels = self._yticks
        else:
            pos = self._auto(self.ylim, self.ylog)
            labels = [_fmt(p) for p in pos]
        for p, lab in zip(self._ty(pos).tolist(), labels):
            if math.isfinite(p) and y0 - 0.5 <= p <= y1 + 0.5:
                d.line([(x0 - 4, p), (x0, p)], fill="#000000")
                f.text((x0 - 6, p), lab, small, anchor="rm")
        f.text(((x0 + x1) / 2, y0 - 8), self.title, f.font(13), anchor="ms")
        f.text(((x0 + x1) / 2, f.height - 6), self.xlabel, f.font(12), anchor="md")
        f.text((max(4, x0 - 86), (y0 + y1) / 2), self.ylabel, f.font(12), anchor="lm", vertical=True)
        if self.legend_items:
            font = f.font(10)
            rows = self.legend_items[:12]
            w = max(f.draw.textlength(lab, font=font) for _, _, lab in rows) + 34
            lx, ly = x1 - w - 6, y0 + 6
            d.rectangle([lx, ly, x1 - 6, ly + 15 * len(rows) + 6], fill="#ffffff", outline="#999999")
            for i, (kind, color, lab) in enumerate(rows):
                cy = ly + 11 + 15 * i
                if kind == "line":
                    d.line([(lx + 6, cy), (lx + 24, cy)], fill=color, width=2)
                elif kind == "box":
                    d.rectangle([lx + 6, cy - 5, lx + 24, cy + 5], fill=color)
                elif kind == "_":
                    d.line([(lx + 8, cy), (lx + 22, cy)], fill=color, width=3)
                elif kind == "x":
                    d.line([(lx + 11, cy - 4), (lx + 19, cy + 4)], fill=color, width=2)
                    d.line([(lx + 11, cy + 4), (lx + 19, cy - 4)], fill=color, width=2)
                else:
                    d.ellipse([lx + 12, cy - 3, lx + 18, cy + 3], fill=color)
                f.text((lx + 30, cy), lab, font, anchor="lm")

    @staticmethod
    def _auto(lim, log: bool) -> list[float]:
        if log:
            lo, hi = math.floor(lim[0]), math.ceil(lim[1])
            step = max(1, int(math.ceil((hi - lo) / 8)))
            # within two decades, 2 and 5 times each decade too
            mult = (1, 2, 5) if lim[1] - lim[0] < 2 else (1,)
            return [m * 10.0 ** e for e in range(lo, hi + 1, step) for m in mult
                    if lim[0] <= math.log10(m * 10.0 ** e) <= lim[1]]
        return _nice_ticks(lim[0], lim[1])


class Figure:
    """A white canvas of ``width`` x ``height`` pixels holding :class:`Axes` panels."""

    def __init__(self, width: int, height: int):
        from PIL import Image, ImageDraw
        self.width, self.height = int(width), int(height)
        self.img = Image.new("RGB", (self.width, self.height), "#ffffff")
        self.draw = ImageDraw.Draw(self.img)
        self.axes: list[Axes] = []
        self._fonts: dict[int, object] = {}

    def font(self, size: int):
        if size not in self._fonts:
            self._fonts[size] = _font(size)
        return self._fonts[size]

    def add_axes(self, x0: int, y0: int, x1: int, y1: int) -> Axes:
        ax = Axes(self, (int(x0), int(y0), int(x1), int(y1)))
        self.axes.append(ax)
        return ax

    def panels(self, n: int, *, left: int = 90, right: int = 20, top: int = 34, bottom: int = 60,
               gap: int = 100) -> list[Axes]:
        """``n`` panels side by side with room for tick labels and titles."""
        w = (self.width - left - right - gap * (n - 1)) / n
        return [self.add_axes(left + i * (w + gap), top, left + i * (w + gap) + w, self.height - bottom)
                for i in range(n)]

    def text(self, xy, s: str, font, anchor: str = "la", vertical: bool = False, fill: str = "#000000") -> None:
        if not s:
            return
        if not vertical:
            self.draw.text(xy, s, font=font, fill=fill, anchor=anchor)
            return
        from PIL import Image, ImageDraw
        w = int(self.draw.textlength(s, font=font)) + 4
        h = int(getattr(font, "size", 11) * 1.4) + 2
        tile = Image.new("RGB", (w, h), "#ffffff")
        ImageDraw.Draw(tile).text((2, h / 2), s, font=font, fill=fill, anchor="lm")
        tile = tile.rotate(90, expand=True)
        x, y = xy
        # anchors used: "lm" (left edge at x, centred on y), "rt" (top end below y, right of x)
        if anchor == "rt":
            box = (int(x - tile.width / 2), int(y))
        else:
            box = (int(x), int(y - tile.height / 2))
        self.img.paste(tile, box)

    def save(self, path: Path) -> str:
        for ax in self.axes:
            ax.finish()
        self.img.save(path, format="PNG", compress_level=1)
        return Path(path).name
