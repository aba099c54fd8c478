"""The house style of every figure fkn-bench writes, and a check that a figure keeps it.

Figures are drawn headless: a :class:`~matplotlib.figure.Figure` on matplotlib's Agg canvas
(no GUI backend is touched and pyplot's global state is never used), laid out by matplotlib's
constrained layout. The style, for figures readable at a glance:

* legends lie outside the data axes (:func:`legend_beside`, :func:`legend_below`), never over data;
* every series is visible on white (no colormap end or colour near white for lines);
* integer-valued axes (epochs, layer counts) are ticked at integers only (:func:`integer_axis`);
* every axis that shows tick labels has a label with its unit in brackets, SI units, ``-`` for
  dimensionless quantities (e.g. ``time (s)``, ``orientation q (-)``); an axis of categories
  (estimators, activation functions) needs only its label;
* no free text inside a data area (annotations go into tick labels, legends or titles), and no two
  texts overlap (tick labels, axis labels, titles, legends, colour bars).

:func:`readability_problems` checks the measurable part of this on a drawn figure; the tests run
it on every figure of the package.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from matplotlib.axes import Axes
from matplotlib.axis import Axis
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.text import Text
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import Bbox

from fkn_bench.io import atomic_path

__all__ = [
    "STATE_RMSE_UNIT",
    "new_figure",
    "legend_beside",
    "legend_below",
    "integer_axis",
    "save_png",
    "readability_problems",
]

STATE_RMSE_UNIT = "mixed SI: -, m, rad/s, m/s"
"""The unit of the 13-state RMSE: the components keep their units (quaternion -, position m, rate
rad/s, velocity m/s; :func:`fkn_bench.metrics.accuracy.state_rmse`)."""

_UNIT = re.compile(r"\([^()]+\)")  # "time (s)", "loss (13-state RMSE, mixed SI: -, m, rad/s, m/s)"
_MAX_LINE_LUMINANCE = 0.85  # relative luminance of a line colour; white is 1, viridis' yellow end ~0.8


def new_figure(width: float, height: float) -> Figure:
    """A ``width`` x ``height`` inch figure on the Agg canvas with constrained layout."""
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def legend_beside(ax: Axes, handles: Sequence[Any] | None = None, *, fontsize: float = 7, **kwargs: Any) -> Legend:
    """A legend to the right of ``ax``, outside its data area (top-aligned); constrained layout
    makes room for it. ``handles`` default to the axes' labelled artists."""
    if handles is not None:
        kwargs["handles"] = list(handles)
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                     fontsize=fontsize, **kwargs)


def legend_below(figure: Figure, handles: Sequence[Any], *, ncols: int = 4, fontsize: float = 8,
                 **kwargs: Any) -> Legend:
    """One legend for the whole figure, centred below all axes (outside every data area)."""
    return figure.legend(handles=list(handles), loc="outside lower center", ncols=ncols, fontsize=fontsize,
                         frameon=False, **kwargs)


def integer_axis(axis: Axis) -> None:
    """Tick ``axis`` (e.g. ``ax.xaxis`` of an epoch axis) at integers only: no 1.25, 1.5 ..."""
    axis.set_major_locator(MaxNLocator(integer=True))


def save_png(figure: Figure, path: str | Path, *, dpi: int = 100) -> Path:
    """Write ``figure`` as PNG atomically; returns the path. (No ``bbox_inches="tight"``: constrained
    layout fits the figure, and :func:`readability_problems` checks that nothing reaches beyond it.)"""
    with atomic_path(path, suffix=".png") as tmp:
        figure.savefig(tmp, format="png", dpi=dpi)
    return Path(path)


# --- the check ---------------------------------------------------------------------------------


def _shown(axes: Axes) -> bool:
    return axes.get_visible() and axes.axison


def _has_data(axes: Axes) -> bool:
    return _shown(axes) and bool(axes.lines or axes.collections or axes.patches or axes.images)


def _tick_labels(axis: Axis) -> list[Text]:
    """The tick labels ``axis`` draws: visible, non-empty, at ticks inside the view limits."""
    if not axis.get_visible():
        return []
    low, high = sorted(axis.get_view_interval())
    slack = 1e-9 * (high - low)
    labels = []
    for ticks in (axis.get_major_ticks(), axis.get_minor_ticks()):
        for tick in ticks:
            if tick.get_loc() is not None and low - slack <= tick.get_loc() <= high + slack:
                labels += [t for t in (tick.label1, tick.label2) if t.get_visible() and t.get_text().strip()]
    return labels


def _categorical(labels: list[Text]) -> bool:
    """Whether the tick labels name categories (estimators, activations) rather than numbers:
    every label has a letter, TeX markup and exponents (``1e-05``, ``10^{-3}``) aside."""
    def words(text: str) -> bool:
        return any(c.isalpha() for c in re.sub(r"\\mathdefault|\\times|\d[eE][+-]?\d", "", text))

    return all(words(t.get_text()) for t in labels)


def _name(axes: Axes, index: int) -> str:
    return f"axes {index} ({axes.get_title() or axes.get_ylabel() or axes.get_xlabel() or 'untitled'})"


def _luminance(colour: Any) -> float:
    linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in to_rgb(colour)]
    return 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]


def _line_colours(axes: Axes) -> Iterable[Any]:
    for line in axes.lines:
        if line.get_visible() and len(line.get_xdata()):
            if line.get_linestyle() not in ("None", "none", "", " "):
                yield line.get_color()
            if line.get_marker() not in (None, "None", "none", "", " "):
                yield line.get_markerfacecolor()
    for collection in axes.collections:
        if isinstance(collection, LineCollection) and collection.get_visible():
            yield from collection.get_colors()


def _overlap(a: Bbox, b: Bbox, slack: float = 1.0) -> bool:
    """Whether ``a`` and ``b`` overlap by more than ``slack`` pixels in both directions."""
    return min(a.x1, b.x1) - max(a.x0, b.x0) > slack and min(a.y1, b.y1) - max(a.y0, b.y0) > slack


def readability_problems(figure: Figure) -> list[str]:
    """What breaks the house style (module docstring) in ``figure``, drawn on its Agg canvas:
    axes whose tick labels have no axis label or no unit in brackets, legends or free text over a
    data area, lines too light to see on white, and overlapping texts (tick labels of one axes on
    another, such as a colour bar). Empty when the figure is fine."""
    if not isinstance(figure.canvas, FigureCanvasAgg):
        FigureCanvasAgg(figure)
    figure.draw_without_rendering()  # layout and tick labels as in a draw, without the pixels
    renderer = figure.canvas.get_renderer()
    problems: list[str] = []
    data_boxes = [(i, ax, ax.get_window_extent(renderer)) for i, ax in enumerate(figure.axes) if _has_data(ax)]
    texts: list[tuple[str, int, Bbox]] = []  # (what, owner axes index or -1, box)

    for i, ax in enumerate(figure.axes):
        if not _shown(ax):
            continue
        for which, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            labels = _tick_labels(axis)
            label = axis.get_label_text().strip()
            if labels and not label:
                problems.append(f"{_name(ax, i)}: {which} axis has tick labels but no label")
            elif labels and not _UNIT.search(label) and not _categorical(labels):
                problems.append(f"{_name(ax, i)}: {which} label {label!r} has no unit in brackets")
            texts += [(f"{which} tick label {t.get_text()!r} of {_name(ax, i)}", i, t.get_window_extent(renderer))
                      for t in labels]
            if label:
                texts.append((f"{which} label {label!r}", i, axis.label.get_window_extent(renderer)))
            offset = axis.get_offset_text()
            if axis.get_visible() and offset.get_visible() and offset.get_text().strip():
                texts.append((f"{which} offset {offset.get_text()!r}", i, offset.get_window_extent(renderer)))
        if ax.get_title():
            texts.append((f"title {ax.get_title()!r}", i, ax.title.get_window_extent(renderer)))
        for colour in _line_colours(ax):
            if _luminance(colour) > _MAX_LINE_LUMINANCE:
                problems.append(f"{_name(ax, i)}: a line of colour {to_rgb(colour)} is nearly invisible on white")
                break
        for text in ax.texts:
            box = text.get_window_extent(renderer)
            if text.get_visible() and text.get_text().strip() and any(_overlap(box, b) for _, _, b in data_boxes):
                problems.append(f"{_name(ax, i)}: text {text.get_text()!r} lies over a data area")

    for legend in [*(ax.get_legend() for ax in figure.axes), *figure.legends]:  # axis-off panels' too
        if legend is None or not legend.get_visible():
            continue
        box = legend.get_window_extent(renderer)
        for j, ax, data in data_boxes:
            if _overlap(box, data):
                problems.append(f"a legend lies over the data of {_name(ax, j)}")
        texts.append(("a legend", -1, box))
    if figure._suptitle is not None and figure._suptitle.get_text():
        texts.append(("the figure title", -1, figure._suptitle.get_window_extent(renderer)))

    page = figure.bbox
    for what, _, box in texts:  # cut off at the figure's edge
        if box.x0 < page.x0 - 1 or box.y0 < page.y0 - 1 or box.x1 > page.x1 + 1 or box.y1 > page.y1 + 1:
            problems.append(f"{what} reaches beyond the figure's edge")
    same_frame = {(i, j) for i, a in enumerate(figure.axes) for j, b in enumerate(figure.axes)
                  if a.get_window_extent(renderer).bounds == b.get_window_extent(renderer).bounds}  # twins
    for what, owner, box in texts:  # an axes' text on another's frame (e.g. tick labels on a colour bar)
        for j, ax in enumerate(figure.axes):
            if owner >= 0 and (owner, j) not in same_frame and _shown(ax) and _overlap(box, ax.get_window_extent(renderer)):
                problems.append(f"{what} lies on the frame of {_name(ax, j)}")
    for k, (what, _, box) in enumerate(texts):
        for other, _, other_box in texts[k + 1:]:
            if _overlap(box, other_box):
                problems.append(f"{what} overlaps {other}")
    return problems
