"""The paper's two training figures: loss curves (Fig. 3) and learned parameters over epochs (Fig. 4).

Headless (matplotlib's Agg backend); files written atomically.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from fkn_bench.io import atomic_path  # noqa: E402

__all__ = ["plot_losses", "plot_parameters", "save_png"]


def save_png(figure: plt.Figure, path: str | Path, *, dpi: int = 130) -> Path:
    """Write ``figure`` as PNG atomically and close it."""
    with atomic_path(path, suffix=".png") as tmp:
        figure.savefig(tmp, dpi=dpi, bbox_inches="tight", format="png")
    plt.close(figure)
    return Path(path)


def plot_losses(history: pd.DataFrame, path: str | Path, *, title: str = "", best_epoch: int | None = None) -> Path:
    """Training and validation loss per epoch (log scale), the best epoch marked."""
    figure, axis = plt.subplots(figsize=(6.4, 3.6))
    axis.plot(history["epoch"], history["train_loss"], label="training loss", color="tab:blue")
    axis.plot(history["epoch"], history["val_loss"], label="validation loss", color="tab:orange")
    if best_epoch:
        axis.axvline(best_epoch, color="0.5", linestyle="--", linewidth=1, label=f"best epoch {best_epoch}")
    axis.set(xlabel="epoch", ylabel="loss (13-state RMSE, or NLL)", title=title)
    if (history[["train_loss", "val_loss"]] > 0).all().all():
        axis.set_yscale("log")
    axis.grid(True, alpha=0.3)
    axis.legend()
    return save_png(figure, path)


def plot_parameters(history: pd.DataFrame, path: str | Path, *, title: str = "") -> Path:
    """The learned standard deviations over epochs: R in one panel, Q in the other (log scale)."""
    figure, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharex=True)
    for axis, tag, label in ((axes[0], "sigma_R_", "measurement noise sigma_R"), (axes[1], "sigma_Q_", "process noise sigma_Q")):
        columns = [c for c in history.columns if c.startswith(tag)]
        colours = plt.cm.tab20(range(len(columns)))  # 13 process-noise lines: distinct colours
        for column, colour in zip(columns, colours):
            axis.plot(history["epoch"], history[column], label=column[len(tag) :], linewidth=1.2, color=colour)
        axis.set(yscale="log", xlabel="epoch", title=label)
        axis.grid(True, alpha=0.3)
        if columns:
            axis.legend(fontsize=7, ncol=2)
    figure.suptitle(title)
    return save_png(figure, path)
