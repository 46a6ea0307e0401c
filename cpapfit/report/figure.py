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


def png(fig: Figure) -> bytes:
    """PNG bytes of a figure (no timestamp or software metadata: same figure, same bytes)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None}, pil_kwargs={"compress_level": 3})
    return buf.getvalue()


def colour_bar(fig: Figure, ax, scale: ColourScale) -> None:
    """A labelled colour bar beside `ax` (an Axes or a list of them), with the scale's marks drawn across it."""
    bar = fig.colorbar(ScalarMappable(Normalize(scale.lo, scale.hi), scale.cmap), ax=ax, fraction=0.035, pad=0.02)
    bar.set_label(scale.label, fontsize=FONT)
    bar.ax.tick_params(labelsize=FONT - 1)
    for value, text in scale.marks:
        bar.ax.axhline(value, color="black", linewidth=1.5)
        bar.ax.annotate(text, (0.0, value), xytext=(-4, 0), textcoords="offset points", ha="right", va="center",
                        fontsize=FONT - 1, xycoords=("axes fraction", "data"))


def panels_png(images: list[np.ndarray], titles: list[str], heading: str, scale: ColourScale | None = None,
               legend: tuple = (), columns: int | None = None) -> bytes:
    """PNG of pictures side by side (in rows of `columns`, default all in one row) with their titles,
    a heading, an optional colour bar and a legend [(colour, label)] of line marks."""
    h, w = images[0].shape[:2]
    columns = columns or len(images)
    rows = -(-len(images) // columns)
    width = columns * w / DPI + (1.4 if scale else 0.2)
    fig = Figure(figsize=(width, rows * (h / DPI + 0.4) + 0.5 + (0.35 if legend else 0.0)), dpi=DPI, layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, columns)).ravel()
    for ax in axes[len(images):]:
        ax.set_axis_off()
    for ax, image, title in zip(axes, images, titles):
        ax.imshow(image, interpolation="nearest")
        ax.set_axis_off()
        ax.set_title(title, fontsize=FONT)
    fig.suptitle(heading, fontsize=FONT + 2, fontweight="bold")
    if scale:
        colour_bar(fig, list(axes), scale)
    if legend:
        handles = [Line2D([], [], color=c, linewidth=5, label=label) for c, label in legend]
        fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=FONT - 1, frameon=False)
    return png(fig)
