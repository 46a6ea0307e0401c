"""Pictures laid out with titles, colour bars and legends (matplotlib's Agg canvas, PNG out).

Every picture that shows a quantity by colour has a labelled colour bar with units."""

import io
from dataclasses import dataclass

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, LinearSegmentedColormap, Normalize, to_rgb
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

DPI = 100
FONT = 11


@dataclass(frozen=True)
class ColourScale:
    """A colour map over [lo, hi] with a label (and unit), and marked values [(value, text)] on its bar."""

    cmap: Colormap
    lo: float
    hi: float
    label: str
    marks: tuple = ()

    def rgb(self, values: np.ndarray) -> np.ndarray:
        """(K, 3) uint8 colours of (K,) values (clipped to the scale)."""
        return np.round(255 * self.cmap(Normalize(self.lo, self.hi, clip=True)(values))[:, :3]).astype(np.uint8)

    def rgb01(self, values: np.ndarray) -> np.ndarray:
        """(K, 3) colours in [0, 1]."""
        return self.rgb(values) / 255.0


def zoned_cmap(lo_frac: float, hi_frac: float) -> Colormap:
    """Blue below a window (lo_frac, hi_frac) of [0, 1], green inside it, orange to red above, with sharp steps at its edges."""
    stops = [(0.0, "#c6dbef", "#c6dbef"), (lo_frac, "#2171b5", "#a1d99b"), (hi_frac, "#006d2c", "#fdae6b"), (1.0, "#a50f15", "#a50f15")]
    data = {ch: [(x, to_rgb(a)[i], to_rgb(b)[i]) for x, a, b in stops] for i, ch in enumerate(("red", "green", "blue"))}
    return LinearSegmentedColormap("zoned", data)


@dataclass(frozen=True)
class Panels:
    """The layout of side-by-side pictures, in pixels: the margin, the gap between pictures, the
    heading's, each title's and the legend's bands, and beside a colour bar the room for its marks'
    names, the bar and its ticks and label."""

    pad: int = 10
    gap: int = 15
    heading: int = 45
    title: int = 35
    legend: int = 35
    bar: tuple = (80, 15, 75)


PANEL = Panels()


def sized_figure(width: int, height: int) -> Figure:
    """A figure of exactly width x height pixels at DPI (Agg truncates its size to whole pixels, so
    the size asked for is half a pixel more)."""
    return Figure(figsize=((width + 0.5) / DPI, (height + 0.5) / DPI), dpi=DPI)


def png(fig: Figure) -> bytes:
    """PNG bytes of a figure (no timestamp or software metadata: same figure, same bytes)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None}, pil_kwargs={"compress_level": 3})
    return buf.getvalue()


def colour_bar(fig: Figure, cax, scale: ColourScale) -> None:
    """A labelled colour bar drawn in the Axes `cax`, with the scale's marks drawn across it and named to its left."""
    bar = fig.colorbar(ScalarMappable(Normalize(scale.lo, scale.hi), scale.cmap), cax=cax)
    bar.set_label(scale.label, fontsize=FONT)
    bar.ax.tick_params(labelsize=FONT - 1)
    for value, text in scale.marks:
        bar.ax.axhline(value, color="black", linewidth=1.5)
        bar.ax.annotate(text, (0.0, value), xytext=(-4, 0), textcoords="offset points", ha="right", va="center",
                        fontsize=FONT - 1, xycoords=("axes fraction", "data"))


def panels_png(images: list[np.ndarray], titles: list[str], heading: str, scale: ColourScale | None = None,
               legend: tuple = (), columns: int | None = None) -> bytes:
    """PNG of (H, W, 3) uint8 pictures, all of one size, side by side (in rows of `columns`, default all
    in one row) at one figure pixel per picture pixel, with their titles, a heading, an optional colour
    bar and a legend [(colour, label)] of line marks, laid out by `PANEL`."""
    h, w = images[0].shape[:2]
    columns = columns or len(images)
    rows = -(-len(images) // columns)
    right = PANEL.pad + columns * w + (columns - 1) * PANEL.gap
    band = rows * (PANEL.title + h)
    width, height = right + (sum(PANEL.bar) if scale else PANEL.pad), PANEL.heading + band + (PANEL.legend if legend else PANEL.pad)
    fig = sized_figure(width, height)
    fig.text(0.5, 1 - PANEL.heading / 2 / height, heading, ha="center", va="center", fontsize=FONT + 2, fontweight="bold")
    for i, (image, title) in enumerate(zip(images, titles)):
        left, top = PANEL.pad + (i % columns) * (w + PANEL.gap), height - PANEL.heading - (i // columns) * (PANEL.title + h)
        fig.figimage(image, xo=left, yo=top - PANEL.title - h, origin="upper")
        fig.text((left + w / 2) / width, (top - PANEL.title / 2) / height, title, ha="center", va="center", fontsize=FONT)
    if scale:
        bottom = height - PANEL.heading - band  # the last row's pictures' bottom edge; the bar runs up to the first's top
        rect = ((right + PANEL.bar[0]) / width, bottom / height, PANEL.bar[1] / width, (band - PANEL.title) / height)
        colour_bar(fig, fig.add_axes(rect), scale)
    if legend:
        handles = [Line2D([], [], color=c, linewidth=5, label=label) for c, label in legend]
        fig.legend(handles=handles, loc="lower center", ncols=len(handles), fontsize=FONT - 1, frameon=False)
    return png(fig)
