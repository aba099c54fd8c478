"""Pictures of the Astrobee environments: ``render_mode="rgb_array"`` frames and the ``"human"`` window.

A frame shows, in the world frame, the body axes (x red, y green, z blue; unit length) of the
true attitude (solid), of the latest estimate, i.e. the last action (dashed), and of the latest
measured attitude (dotted, thin); its title gives the scenario, seed, step and time and the
attitude error of the estimate (sign-safe angle between estimate and truth, degrees) and its
position error (m). A second panel traces the attitude error over the last
:data:`HISTORY_STEPS` estimates (kept by the environment while it renders). Drawn with matplotlib: an Agg canvas for ``rgb_array`` (no GUI,
no pyplot state), a pyplot window for ``human`` (which needs an interactive backend, i.e. a
display; without one, ``human`` warns once and draws nothing, so that Gymnasium's
``check_env``, which makes every declared mode, passes on a headless machine).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.types import ArrayF

__all__ = ["FrameState", "PoseRenderer", "HISTORY_STEPS", "display_problem"]

HISTORY_STEPS = 300
"""Estimates traced in the attitude-error panel."""

_AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")  # body x, y, z
_SOURCES = (("truth", "-", 2.4, 1.0), ("estimate", "--", 2.0, 1.0), ("measurement", ":", 1.4, 0.8))


@dataclass(frozen=True)
class FrameState:
    """What one frame shows.

    Attributes:
        title: the episode, e.g. ``"ds1 seed 3"``.
        step: the step shown (that of the latest estimate, else of the current observation).
        time: its time, s.
        truth: the true state ``(13,)`` at that step.
        estimate: the latest estimate ``(13,)`` (the action), or None before the first step.
        measurement: the latest measured pose ``[q, r]`` ``(7,)`` up to that step, or None.
        measured_now: whether that step had a measurement.
        history: times (s) and attitude errors (deg) of the latest estimates, oldest first.
    """

    title: str
    step: int
    time: float
    truth: ArrayF
    estimate: ArrayF | None
    measurement: ArrayF | None
    measured_now: bool
    history: tuple[ArrayF, ArrayF] = (np.empty(0), np.empty(0))


def display_problem() -> str | None:
    """Why ``render_mode="human"`` cannot open a window here (matplotlib has no interactive
    backend: no display, or ``MPLBACKEND`` names a file backend), or None if it can."""
    import matplotlib
    from matplotlib import pyplot  # noqa: F401  (resolves the backend)

    backend = matplotlib.get_backend().lower()
    if backend in ("agg", "pdf", "ps", "svg", "pgf", "cairo", "template") or backend.startswith("module://"):
        return (f"render_mode='human' has no window to draw in: matplotlib's backend is {backend!r} (no display, "
                "or MPLBACKEND set), so nothing is drawn. Use render_mode='rgb_array' "
                "(e.g. with gymnasium.wrappers.RecordVideo) for frames")
    return None


class PoseRenderer:
    """Draws :class:`FrameState` s on one figure, reused frame after frame.

    Args:
        interactive: a pyplot window (``render_mode="human"``; needs :func:`display_problem` to
            be None) instead of an off-screen canvas.
        fps: frames per second of the window (``human``: each frame pauses ``1 / fps`` s).
        size: figure size in inches (at 100 dpi: 768 x 384 pixels by default, multiples of 16 as
            video codecs want).
    """

    def __init__(self, *, interactive: bool = False, fps: float = 10.0, size: tuple[float, float] = (7.68, 3.84)) -> None:
        self._interactive = bool(interactive)
        self._pause = 1.0 / max(float(fps), 1e-3)
        if self._interactive:
            from matplotlib import pyplot

            self._pyplot = pyplot
            self.figure = pyplot.figure(figsize=size, dpi=100)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.figure = Figure(figsize=size, dpi=100)
            FigureCanvasAgg(self.figure)
        self._build()

    def _build(self) -> None:
        from matplotlib.lines import Line2D

        figure = self.figure
        grid = figure.add_gridspec(1, 2, width_ratios=(1.0, 1.15), left=0.02, right=0.97, bottom=0.2, top=0.82, wspace=0.3)
        ax = figure.add_subplot(grid[0, 0], projection="3d")
        ax.set(xlim=(-1, 1), ylim=(-1, 1), zlim=(-1, 1), xlabel="x (-)", ylabel="y (-)", zlabel="z (-)")
        ax.set_box_aspect((1, 1, 1))
        ax.set(xticks=(-1, 0, 1), yticks=(-1, 0, 1), zticks=(-1, 0, 1))
        ax.tick_params(labelsize=6, pad=0)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.label.set_size(7)
            axis.labelpad = -6
        self._lines: dict[str, list] = {}
        for name, style, width, alpha in _SOURCES:
            self._lines[name] = [
                ax.plot([0, 0], [0, 0], [0, 0], linestyle=style, linewidth=width, color=colour, alpha=alpha)[0]
                for colour in _AXIS_COLOURS
            ]
        handles = [Line2D([], [], color="0.3", linestyle=style, linewidth=width) for _, style, width, _ in _SOURCES]
        handles += [Line2D([], [], color=c, linewidth=2) for c in _AXIS_COLOURS]
        labels = [name for name, *_ in _SOURCES] + ["body x", "body y", "body z"]
        figure.legend(handles, labels, loc="lower center", ncol=6, fontsize=7, frameon=False)
        self._attitude_axes = ax
        trace = figure.add_subplot(grid[0, 1])
        trace.set_xlabel("time (s)", fontsize=8)
        trace.set_ylabel("attitude error (deg)", fontsize=8)
        trace.tick_params(labelsize=7)
        (self._trace,) = trace.plot([], [], color="0.2", linewidth=1.2)
        self._trace_axes = trace
        self._title = figure.suptitle("", fontsize=8)

    def _set_axes(self, name: str, q: ArrayF | None) -> None:
        lines = self._lines[name]
        if q is None or not np.all(np.isfinite(q)) or not np.any(q):
            for line in lines:
                line.set_visible(False)
            return
        matrix = quat.rotation_matrix(quat.normalize(np.asarray(q, dtype=float)))
        for column, line in enumerate(lines):
            tip = matrix[:, column]
            line.set_data_3d([0.0, tip[0]], [0.0, tip[1]], [0.0, tip[2]])
            line.set_visible(True)

    def draw(self, state: FrameState) -> None:
        """Update the figure to ``state`` (and, for a window, show it)."""
        self._set_axes("truth", state.truth[:4])
        self._set_axes("estimate", None if state.estimate is None else state.estimate[:4])
        self._set_axes("measurement", None if state.measurement is None else state.measurement[:4])
        headline = f"{state.title}   step {state.step}   t = {state.time:.2f} s   " + (
            "measured" if state.measured_now else "no measurement")
        if state.estimate is not None:
            angle = float(np.degrees(quat.angle_between(state.truth[:4], quat.normalize(state.estimate[:4]))))
            position = float(np.linalg.norm(state.estimate[4:7] - state.truth[4:7]))
            headline += f"\nattitude error {angle:.2f} deg   position error {position:.3f} m"
        else:
            headline += "\nno estimate yet"
        self._title.set_text(headline)
        times, angles = state.history
        if len(times):
            self._trace.set_data(times, angles)
            low, high = float(times[0]), float(times[-1])
            self._trace_axes.set_xlim(low, high if high > low else low + 1.0)
            self._trace_axes.set_ylim(0.0, max(1.0, 1.1 * float(angles.max())))
        else:
            self._trace.set_data([], [])
        if self._interactive:
            self.figure.canvas.draw_idle()
            self._pyplot.pause(self._pause)

    def rgb_array(self, state: FrameState) -> np.ndarray:
        """The frame of ``state``: ``uint8 (H, W, 3)``."""
        self.draw(state)
        canvas = self.figure.canvas
        canvas.draw()
        return np.array(canvas.buffer_rgba())[..., :3]

    def close(self) -> None:
        if self._interactive:
            self._pyplot.close(self.figure)
