"""Matplotlib figures for the reports: a headless backend, atomic PNG writing, one style per
series and legends that never cover the data."""
from __future__ import annotations

import math
from typing import NamedTuple

from ..images import atomic_path

#: Markers and line styles of the second varying factor of a series' key (the sampler):
#: the n-th value gets the n-th of each, so neighbours differ in both.
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">", "h", "p")
LINESTYLES = ("-", "--", ":", "-.")
#: A legend right of the axes gets a second column past this many entries.
LEGEND_ROWS = 20


class Style(NamedTuple):
    colour: str
    marker: str
    linestyle: str

    def kwargs(self) -> dict:
        """Keyword arguments for ``ax.plot`` / ``ax.errorbar``."""
        return {"color": self.colour, "marker": self.marker, "linestyle": self.linestyle}


def _ordered(values) -> list:
    return list(dict.fromkeys(values))


def series_styles(keys, factors: tuple[str, ...] | None = None) -> tuple[dict, str]:
    """A distinct (colour, marker, line style) per series key, grouped by factor.

    ``keys`` are tuples of factors (a report's (strategy, sampler)) or plain strings. The
    first factor that varies between the keys picks the colour (tab10, tab20 past 10
    values), the other varying factors together the marker and line style, so a group
    shares a colour and a sampler a marker across groups. Pairs (colour, marker) are
    distinct for up to 20 colours x 12 markers. Returns ({key: Style}, how to read it, e.g.
    "colour: strategy, marker and line: sampler" when ``factors`` names the factors, else "").
    The styles depend only on the set and order of the keys, so plots of one scene that
    draw the same keys draw them alike."""
    keys = _ordered(keys)
    tuples = [k if isinstance(k, tuple) else (k,) for k in keys]
    width = max((len(t) for t in tuples), default=0)
    part = lambda t, i: t[i] if i < len(t) else None            # noqa: E731
    varying = [i for i in range(width) if len({part(t, i) for t in tuples}) > 1] or [0]
    first, rest = varying[0], varying[1:]
    colours = _ordered(part(t, first) for t in tuples)
    kinds = _ordered(tuple(part(t, i) for i in rest) for t in tuples)
    palette = [f"C{i}" for i in range(10)] if len(colours) <= 10 else _tab20()
    styles = {}
    for key, t in zip(keys, tuples):
        c = colours.index(part(t, first))
        # past the palette, colours repeat: move on to the next set of markers
        j = kinds.index(tuple(part(t, i) for i in rest)) + (c // len(palette)) * len(kinds)
        styles[key] = Style(palette[c % len(palette)], MARKERS[j % len(MARKERS)], LINESTYLES[j % len(LINESTYLES)])
    legend = ""
    if factors and rest and len(factors) > max(rest):
        legend = f"colour: {factors[first]}, marker and line: {' / '.join(factors[i] for i in rest)}"
    return styles, legend


def _tab20() -> list[str]:
    from matplotlib import colormaps
    from matplotlib.colors import to_hex

    cmap = colormaps["tab20"]
    # dark shades first, then the light ones: neighbouring groups differ in hue and shade
    return [to_hex(cmap(i)) for i in list(range(0, 20, 2)) + list(range(1, 20, 2))]


def legend_outside(ax, fontsize: float = 7, title: str = "", max_rows: int = LEGEND_ROWS):
    """The axes' legend right of them (upper left corner at the axes' upper right), with
    ceil(entries / max_rows) columns, so it never covers the data; None when nothing is
    labelled. Saved with ``save_figure`` (tight bounding box) the figure grows to hold it."""
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return None
    return ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                     ncol=math.ceil(len(handles) / max_rows), fontsize=fontsize, title=title or None,
                     title_fontsize=fontsize, frameon=False)


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


def loglog_axes(ax, xlabel: str, ylabel: str, title: str, legend_size: float = 8,
                title_size: float | None = None, legend_title: str = ""):
    """Log-log axes with labels, title, a light grid on major and minor ticks and the
    legend outside them (``legend_outside``); returns the legend (None without one)."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, **({"fontsize": title_size} if title_size else {}))
    ax.grid(True, which="both", alpha=0.3)
    return legend_outside(ax, legend_size, legend_title)


def save_loglog(fig, ax, path: str, xlabel: str, ylabel: str, title: str, legend_size: float = 8,
                title_size: float | None = None, legend_title: str = "") -> str:
    """``loglog_axes``, then ``save_figure``; returns ``path``."""
    loglog_axes(ax, xlabel, ylabel, title, legend_size, title_size, legend_title)
    return save_figure(fig, path)
