"""PNG figures of the virtual workpiece drawn with Pillow: a raster panel (optionally with axes in
mm), a colour bar with its unit, a title.

Why not matplotlib: importing pyplot and drawing a scatter of 10^5..10^6 points or a collection of
10^5 triangles took longer than the whole coupled machining loop of a test piece. Here the part is
rasterised directly (a z-buffer: the surface nearest the viewer wins each pixel) and only text and
lines are drawn; the colours are matplotlib's viridis (the colour table only, no pyplot).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

#: Background and ink colours (RGB).
WHITE = (255, 255, 255)
INK = (30, 30, 30)
#: Smallest panel [px]: a smaller raster is enlarged by whole pixels.
MIN_PANEL_PX = 400
#: Smallest colour bar height [px].
MIN_BAR_PX = 240


def viridis_table() -> np.ndarray:
    """matplotlib's viridis (van der Walt and Smith 2015) as (256, 4) RGBA uint8 (sRGB): the colour
    table alone (``matplotlib.colormaps`` without pyplot, a tenth of a second)."""
    from matplotlib import colormaps

    return np.round(colormaps["viridis"](np.arange(256)) * 255).astype(np.uint8)


def viridis(norm) -> np.ndarray:
    """RGBA uint8 (sRGB) viridis colours of values in 0..1 (clipped), indexed as matplotlib's
    Colormap does (``int(x * 256)``, x = 1 -> the last entry)."""
    idx = np.minimum((np.clip(norm, 0.0, 1.0) * 256).astype(np.intp), 255)
    return viridis_table()[idx]


def font(size: int):
    """DejaVu Sans (shipped with matplotlib, found without importing it: it has the micro sign) at
    ``size`` pixels, else Pillow's own font."""
    import importlib.util
    from pathlib import Path

    from PIL import ImageFont

    try:
        spec = importlib.util.find_spec("matplotlib")
        root = Path(next(iter((spec.submodule_search_locations if spec else None) or [])))
        return ImageFont.truetype(str(root / "mpl-data" / "fonts" / "ttf" / "DejaVuSans.ttf"), size)
    except (OSError, AttributeError, StopIteration, TypeError):  # pragma: no cover - matplotlib ships it
        return ImageFont.load_default(size)


def nice_ticks(lo: float, hi: float, n: int = 6) -> np.ndarray:
    """About ``n`` round tick values (1, 2, 5 x 10^k steps) inside ``lo..hi``."""
    span = hi - lo
    if not (math.isfinite(span) and span > 0):
        return np.array([lo])
    raw = span / max(n - 1, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = min((m * mag for m in (1, 2, 5, 10) if m * mag >= raw), default=10 * mag)
    first = math.ceil(lo / step - 1e-9) * step
    ticks = np.arange(first, hi + step * 1e-9, step)
    return np.round(ticks / step) * step


def _label(v: float) -> str:
    return f"{v:.6g}" if abs(v) >= 1e-12 else "0"


class Panel(NamedTuple):
    """A raster panel: ``rgb`` (H, W, 3) uint8, row 0 at the top; ``extent_mm`` (x0, x1, y0, y1) of
    its pixel edges for axes in mm, or None (no axes)."""

    rgb: np.ndarray
    extent_mm: tuple | None = None


class ColourBar(NamedTuple):
    """A colour bar: ``lo``..``hi`` in display units, its label, and an optional grey note."""

    lo: float
    hi: float
    label: str
    note: str | None = None


def _vertical_text(text: str, fnt, fill=INK):
    from PIL import Image, ImageDraw

    w, h = _text_size(text, fnt)
    im = Image.new("RGBA", (w + 4, h + 4), (255, 255, 255, 0))
    ImageDraw.Draw(im).text((2, 2), text, font=fnt, fill=fill)
    return im.rotate(90, expand=True)


def _text_size(text: str, fnt) -> tuple[int, int]:
    left, top, right, bottom = fnt.getbbox(text)
    return int(right - min(left, 0)) + 1, int(bottom - min(top, 0)) + 1


def colour_bar_image(bar: ColourBar, height: int, size: int = 13):
    """The colour bar alone (RGB image): gradient, ticks with values, the label along it."""
    from PIL import Image, ImageDraw

    fnt = font(size)
    ticks = nice_ticks(bar.lo, bar.hi)
    labels = [_label(v) for v in ticks]
    tw = max((_text_size(s, fnt)[0] for s in labels), default=0)
    label_im = _vertical_text(bar.label, fnt)
    bw, pad = 22, 8
    width = pad + bw + 5 + tw + pad + label_im.width + pad
    im = Image.new("RGB", (width, height), WHITE)
    top, bottom = 10, height - 10
    frac = 1.0 - (np.arange(bottom - top) + 0.5) / (bottom - top)
    grad = viridis(frac)[:, None, :3].repeat(bw, axis=1)
    im.paste(Image.fromarray(np.ascontiguousarray(grad), "RGB"), (pad, top))
    d = ImageDraw.Draw(im)
    d.rectangle([pad, top, pad + bw, bottom], outline=INK)
    span = bar.hi - bar.lo if bar.hi > bar.lo else 1.0
    for v, s in zip(ticks, labels, strict=True):
        y = bottom - (v - bar.lo) / span * (bottom - top)
        d.line([pad + bw, y, pad + bw + 4, y], fill=INK)
        d.text((pad + bw + 6, y), s, font=fnt, fill=INK, anchor="lm")
    im.paste(label_im, (pad + bw + 5 + tw + pad, (height - label_im.height) // 2), label_im)
    return im


def figure(panel: Panel, bar: ColourBar, title: str, size: int = 14):
    """Panel, axes (when the panel has an extent), colour bar and title as one RGB image."""
    from PIL import Image, ImageDraw

    fnt, small = font(size + 2), font(size)
    img = Image.fromarray(np.ascontiguousarray(panel.rgb[..., :3]), "RGB")
    k = MIN_PANEL_PX // max(img.width, img.height, 1)
    if k > 1:   # a small part: whole pixels enlarged, not interpolated
        img = img.resize((img.width * k, img.height * k), Image.Resampling.NEAREST)
    left, top = (70 if panel.extent_mm else 20), 40
    bottom = 60 if panel.extent_mm else 20 + 10 * bool(bar.note)
    cb = colour_bar_image(bar, max(img.height, MIN_BAR_PX), size)
    note_w = _text_size(bar.note, small)[0] if bar.note else 0
    W = left + img.width + 20 + max(cb.width, note_w) + 10
    H = top + max(img.height, cb.height) + bottom
    fig = Image.new("RGB", (W, H), WHITE)
    fig.paste(img, (left, top))
    fig.paste(cb, (left + img.width + 20, top))
    d = ImageDraw.Draw(fig)
    d.text((left + img.width / 2, top / 2), title, font=fnt, fill=INK, anchor="mm")
    if bar.note:
        d.text((left + img.width + 20, top + cb.height + 4), bar.note, font=small, fill=INK, anchor="la")
    if panel.extent_mm:
        x0, x1, y0, y1 = panel.extent_mm
        d.rectangle([left - 1, top - 1, left + img.width, top + img.height], outline=INK)
        for v in nice_ticks(x0, x1, 8):
            x = left + (v - x0) / (x1 - x0) * img.width
            d.line([x, top + img.height, x, top + img.height + 4], fill=INK)
            d.text((x, top + img.height + 6), _label(v), font=small, fill=INK, anchor="ma")
        for v in nice_ticks(y0, y1, 8):
            y = top + img.height - (v - y0) / (y1 - y0) * img.height
            d.line([left - 5, y, left - 1, y], fill=INK)
            d.text((left - 7, y), _label(v), font=small, fill=INK, anchor="rm")
        d.text((left + img.width / 2, H - 14), "x [mm]", font=small, fill=INK, anchor="mm")
        ylab = _vertical_text("y [mm]", small)
        fig.paste(ylab, (2, top + (img.height - ylab.height) // 2), ylab)
    return fig


def top_view(points: np.ndarray, colours: np.ndarray, pixel: float, background=WHITE) -> Panel:
    """Top view (looking down -z) of coloured points: each pixel of size ``pixel`` [m] shows the
    colour of its highest point. ``points`` (N, 3) [m], ``colours`` (N, 3|4) uint8."""
    lo = points[:, :2].min(axis=0)
    hi = points[:, :2].max(axis=0)
    # pixel centres on the extreme points: points on a lattice of that pitch (dexel centres) fall
    # mid-pixel, not on pixel edges where round-off would leave rows empty
    lo, hi = lo - 0.5 * pixel, hi + 0.5 * pixel
    w, h = np.maximum(np.ceil((hi - lo) / pixel - 1e-6).astype(int), 1)
    ix = np.clip(np.floor((points[:, 0] - lo[0]) / pixel).astype(np.int64), 0, w - 1)
    iy = np.clip(np.floor((hi[1] - points[:, 1]) / pixel).astype(np.int64), 0, h - 1)   # row 0 at the top
    pix = iy * w + ix
    order = np.lexsort((points[:, 2], pix))          # by pixel, then height: the last of a pixel is the top
    pix_s = pix[order]
    last = np.r_[pix_s[1:] != pix_s[:-1], True]
    rgb = np.empty((h * w, 3), np.uint8)
    rgb[:] = background
    rgb[pix_s[last]] = colours[order[last], :3]
    ext = (lo[0] * 1e3, (lo[0] + w * pixel) * 1e3, (hi[1] - h * pixel) * 1e3, hi[1] * 1e3)
    return Panel(rgb.reshape(h, w, 3), ext)


class Triangles(NamedTuple):
    """Projected triangles for :func:`_raster_triangles`: ``xy`` (T, 3, 2) pixel coordinates,
    ``depth`` (T, 3) distance from the viewer (smaller is nearer), ``rgb`` (T, 3) uint8."""

    xy: np.ndarray
    depth: np.ndarray
    rgb: np.ndarray


@njit(cache=True)
def _raster_triangles(tri, zbuf, image):
    """Fill each triangle's pixels (centres inside it) where it is nearer than ``zbuf`` holds."""
    h, w = zbuf.shape
    for t in range(tri.xy.shape[0]):
        x0, y0 = tri.xy[t, 0, 0], tri.xy[t, 0, 1]
        x1, y1 = tri.xy[t, 1, 0], tri.xy[t, 1, 1]
        x2, y2 = tri.xy[t, 2, 0], tri.xy[t, 2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0:
            continue
        i0 = max(int(math.floor(min(x0, x1, x2))), 0)
        i1 = min(int(math.ceil(max(x0, x1, x2))), w - 1)
        j0 = max(int(math.floor(min(y0, y1, y2))), 0)
        j1 = min(int(math.ceil(max(y0, y1, y2))), h - 1)
        for j in range(j0, j1 + 1):
            py = j + 0.5
            for i in range(i0, i1 + 1):
                px = i + 0.5
                w0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) / area
                w1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) / area
                w2 = 1.0 - w0 - w1
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                z = w0 * tri.depth[t, 0] + w1 * tri.depth[t, 1] + w2 * tri.depth[t, 2]
                if z < zbuf[j, i]:
                    zbuf[j, i] = z
                    image[j, i, 0] = tri.rgb[t, 0]
                    image[j, i, 1] = tri.rgb[t, 1]
                    image[j, i, 2] = tri.rgb[t, 2]


def raster_triangles(xy: np.ndarray, depth: np.ndarray, rgb: np.ndarray, width: int, height: int,
                     background=WHITE) -> np.ndarray:
    """Rasterise flat-coloured triangles with a z-buffer into an (height, width, 3) uint8 image.
    ``xy`` (T, 3, 2) in pixels (x right, y down), ``depth`` (T, 3) (smaller: nearer), ``rgb`` (T, 3)."""
    image = np.empty((height, width, 3), np.uint8)
    image[:] = background
    zbuf = np.full((height, width), np.inf)
    tri = Triangles(np.ascontiguousarray(xy, np.float64), np.ascontiguousarray(depth, np.float64),
                    np.ascontiguousarray(rgb[:, :3], np.uint8))
    _raster_triangles(tri, zbuf, image)
    return image


def save_png(image, path) -> None:
    """Write a Pillow image as PNG to ``path`` atomically (:func:`identify.files.atomic_file`: nothing
    half written, the umask's mode)."""
    from identify.files import atomic_file

    with atomic_file(path) as tmp:
        image.save(tmp, format="PNG", compress_level=3)
