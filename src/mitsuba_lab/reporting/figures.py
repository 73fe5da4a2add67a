"""Matplotlib figures for the reports: a headless backend and atomic PNG writing."""
from __future__ import annotations

from ..images import atomic_path


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (reports are written
    without a display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str) -> str:
    """Write ``fig`` as a PNG at ``path`` (atomically, tight bounding box) and close it;
    returns ``path``."""
    plt = pyplot()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)
    return path


def save_loglog(fig, ax, path: str, xlabel: str, ylabel: str, title: str, legend_size: float = 8,
                title_size: float | None = None) -> str:
    """Log-log axes with labels, title, a light grid on major and minor ticks and a legend,
    then ``save_figure``; returns ``path``."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, **({"fontsize": title_size} if title_size else {}))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=legend_size)
    return save_figure(fig, path)
