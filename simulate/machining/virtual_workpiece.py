"""The virtual workpiece: dexel model plus per-step process values, saved, probed and exported
(paper section 3.3 "Generating a Virtual Workpiece Model", 3.8).

Every dexel end stores the index of the step that created it; :func:`end_attributes` gathers the
step values (time, program line, force, deflection, tracking error, switching bits) per end.
Export: a closed triangle surface whose vertices sit on the exact dexel ends
(:mod:`simulate.machining.surface_mesh`), as GLB and PLY with vertex colours of a chosen variable,
and PNG renderings with a colour bar.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from identify.errors import InputError
from identify.files import atomic_file

from .dexel import RayFamily, TriDexel
from .simulation import StepTable

VARIABLES = ("deflection", "force", "tracking_error", "time", "line", "switch", "peak_force")


def _savez_fast(path, arrays: dict) -> None:
    """``numpy.savez_compressed`` at zlib level 1: about a third of the time of its default level 6
    for the dexel arrays, a slightly larger file, the same arrays read back by ``numpy.load``."""
    import zipfile

    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1, allowZip64=True) as zf:
        for name, a in arrays.items():
            with zf.open(name + ".npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asanyarray(a), allow_pickle=False)


@dataclass
class VirtualWorkpiece:
    workpiece: TriDexel
    steps: StepTable

    def save(self, path) -> Path:
        """Write an npz atomically (temp file + rename)."""
        p = Path(path)
        arrays = {"lower": self.workpiece.lower, "upper": self.workpiece.upper,
                  "spacing": np.array(self.workpiece.spacing), "shape": np.array(self.workpiece.shape)}
        for f in self.workpiece.families:
            for name in ("lo", "hi", "lo_step", "hi_step", "count"):
                arrays[f"f{f.axis}_{name}"] = getattr(f, name)
        arrays.update(self.steps.as_arrays())
        with atomic_file(p) as tmp:
            _savez_fast(tmp, arrays)
        return p

    @classmethod
    def load(cls, path) -> VirtualWorkpiece:
        p = Path(path)
        if not p.exists():
            raise InputError("virtual workpiece not found", source=str(p))
        z = np.load(p)
        fams = [RayFamily(a, z[f"f{a}_lo"], z[f"f{a}_hi"], z[f"f{a}_lo_step"], z[f"f{a}_hi_step"], z[f"f{a}_count"])
                for a in range(3)]
        nx, ny, nz = (int(v) for v in z["shape"])
        wp = TriDexel(z["lower"], z["upper"], float(z["spacing"]), (nx, ny, nz), fams)
        st = StepTable(*(z[f"step_{k}"] for k in StepTable.__dataclass_fields__))
        return cls(wp, st)

    def end_attributes(self, axis: int):
        """Dexel ends of one family: points (M, 3) [m], outward sign (M,), and a dict of per-end
        arrays of the creating step's values (NaN / 0 for stock-surface ends)."""
        pts, step, sign = self.workpiece.ends(axis)
        ok = step >= 0
        attrs = {}
        for name in VARIABLES:
            col = getattr(self.steps, "t" if name == "time" else name)
            shape = (len(step),) + col.shape[1:]
            a = np.full(shape, np.nan if col.dtype.kind == "f" else 0, dtype=col.dtype)
            a[ok] = col[step[ok]]
            attrs[name] = a
        attrs["step"] = step
        return pts, sign, attrs

    def probe(self, origin, direction):
        """First material surface hit along axis-aligned rays (the virtual CMM's probe).

        ``origin`` (N, 3) [m], ``direction`` (N, 3) unit vectors along +-x, +-y or +-z. The probe runs
        on the nearest dexel ray of that axis and returns hit points (N, 3) (NaN where no
        material) with the exact dexel-end coordinate along the axis.
        """
        o = np.atleast_2d(np.asarray(origin, float))
        d = np.atleast_2d(np.asarray(direction, float))
        hits = np.full_like(o, np.nan)
        wp = self.workpiece
        for i in range(len(o)):
            axis = int(np.argmax(np.abs(d[i])))
            if abs(abs(d[i, axis]) - 1) > 1e-9:
                raise InputError("probe directions must be along x, y or z", field="direction", row=i)
            sgn = np.sign(d[i, axis])
            others = [a for a in range(3) if a != axis]
            idx = np.floor((o[i, others] - wp.lower[others]) / wp.spacing).astype(int)
            n_o = [wp.shape[a] for a in others]
            if not (0 <= idx[0] < n_o[0] and 0 <= idx[1] < n_o[1]):
                continue
            r = {0: idx[1] * n_o[0] + idx[0], 1: idx[1] * n_o[0] + idx[0], 2: idx[1] * n_o[0] + idx[0]}[axis]
            f = wp.families[axis]
            lo, hi = f.lo[r, :f.count[r]], f.hi[r, :f.count[r]]
            if sgn > 0:
                cand = lo[lo >= o[i, axis]]
                if len(cand) == 0:
                    continue
                val = cand.min()
            else:
                cand = hi[hi <= o[i, axis]]
                if len(cand) == 0:
                    continue
                val = cand.max()
            hits[i] = o[i]
            hits[i, others] = wp.lower[others] + (idx + 0.5) * wp.spacing
            hits[i, axis] = val
        return hits


def _scalar(attrs, variable):
    v = attrs[variable]
    return np.linalg.norm(v, axis=1) if v.ndim == 2 else v.astype(float)


def machined_points(vw: VirtualWorkpiece, variable: str = "deflection"):
    """Machined surface points (dexel ends created by the simulation) with a scalar per point."""
    if variable not in VARIABLES:
        raise InputError(f"unknown variable '{variable}' (one of {', '.join(VARIABLES)})", field="variable")
    P, V = [], []
    for axis in range(3):
        pts, sign, attrs = vw.end_attributes(axis)
        ok = attrs["step"] >= 0
        P.append(pts[ok])
        V.append(_scalar(attrs, variable)[ok])
    return np.concatenate(P), np.concatenate(V)


#: Display unit of each variable: (factor from SI, label) for legends and renderings.
DISPLAY_UNITS = {"deflection": (1e6, "µm"), "tracking_error": (1e6, "µm"), "force": (1.0, "N"),
                 "peak_force": (1.0, "N"), "time": (1.0, "s"), "line": (1.0, "-"), "switch": (1.0, "bits")}
#: RGBA of the stock surface (not machined) [0..255].
STOCK_GREY = (200, 200, 200, 255)


def colour_range(values) -> tuple[float, float]:
    """The colour scale's ends (SI): the smallest and largest finite value, so every machined
    vertex, features included, gets a colour inside the scale and none is clipped to an end colour.
    A constant field gets a scale of width 1 (SI) around nothing: ``(v, v + 1)``."""
    v = np.asarray(values, float)
    ok = np.isfinite(v)
    if not ok.any():
        return 0.0, 1.0
    lo, hi = float(v[ok].min()), float(v[ok].max())
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def _colours(values, lo: float | None = None, hi: float | None = None):
    """RGBA (uint8, sRGB) viridis colours of ``values`` over ``lo..hi`` (default:
    :func:`colour_range`); NaN (stock surface) -> light grey. Returns ``(colours, lo, hi)``."""
    v = np.asarray(values, float)
    ok = np.isfinite(v)
    if lo is None or hi is None:
        lo, hi = colour_range(v)
    norm = np.clip(np.where(ok, (np.nan_to_num(v) - lo) / (hi - lo), 0.0), 0.0, 1.0)
    from .raster_figure import viridis

    # matplotlib's 256-entry table, indexed as its Colormap does: the same colours in a tenth of the time
    cols = viridis(norm)
    cols[~ok] = STOCK_GREY
    return cols, lo, hi


def srgb_to_linear(rgba: np.ndarray) -> np.ndarray:
    """uint8 sRGB(A) colours -> uint8 linear RGB(A) (alpha kept): glTF's vertex colours (COLOR_0)
    are linear, viewers encode them to sRGB for display; writing sRGB values there would show every
    colour lighter and the map washed out (IEC 61966-2-1 transfer function)."""
    c = np.asarray(rgba, float) / 255.0
    out = c.copy()
    rgb = c[..., :3]
    out[..., :3] = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return np.round(out * 255.0).astype(np.uint8)


def legend_png(variable: str, lo: float, hi: float) -> bytes:
    """The colour legend of a coloured part as PNG bytes: viridis from ``lo`` to ``hi`` (SI) labelled
    in the variable's display unit, and the stock-surface grey
    (:func:`simulate.machining.raster_figure.colour_bar_image`)."""
    import io

    from PIL import Image, ImageDraw

    from .raster_figure import INK, ColourBar, colour_bar_image, font

    factor, unit = DISPLAY_UNITS[variable]
    bar = colour_bar_image(ColourBar(lo * factor, hi * factor, f"{variable.replace('_', ' ')} [{unit}]"), 440)
    im = Image.new("RGB", (max(bar.width, 150) + 20, 500), (255, 255, 255))
    im.paste(bar, (10, 10))
    d = ImageDraw.Draw(im)
    d.rectangle([18, 462, 40, 480], fill=STOCK_GREY[:3], outline=INK)
    d.text((48, 471), "stock surface", font=font(13), fill=INK, anchor="lm")
    buf = io.BytesIO()
    im.save(buf, format="PNG")
    return buf.getvalue()


def _legend_quad(png: bytes, bounds: np.ndarray):
    """A rectangle showing the legend, standing beside the part (+x side, facing -y), as tall as
    the part is deep in y (at least 40 mm): (vertices (4, 3) [m], faces (2, 3), uv (4, 2))."""
    import io

    from PIL import Image

    w_px, h_px = Image.open(io.BytesIO(png)).size
    size = bounds[1] - bounds[0]
    height = max(float(size[1]) * 0.8, 0.04)
    width = height * w_px / h_px
    x0 = float(bounds[1][0]) + 0.05 * max(float(size[0]), 0.02)
    y0 = float(bounds[0][1]) + 0.1 * float(size[1])
    z0 = float(bounds[0][2])
    vertices = np.array([[x0, y0, z0], [x0 + width, y0, z0], [x0 + width, y0, z0 + height], [x0, y0, z0 + height]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])   # glTF: v = 0 at the image's top row
    return vertices, faces, uv


def step_values(vw: VirtualWorkpiece, step: np.ndarray, variable: str = "deflection") -> np.ndarray:
    """Scalar of ``variable`` (vector variables: magnitude) for step indices; NaN where step < 0."""
    if variable not in VARIABLES:
        raise InputError(f"unknown variable '{variable}' (one of {', '.join(VARIABLES)})", field="variable")
    col = getattr(vw.steps, "t" if variable == "time" else variable)
    col = np.linalg.norm(col, axis=1) if col.ndim == 2 else col.astype(float)
    out = np.full(len(step), np.nan)
    ok = step >= 0
    out[ok] = col[step[ok]]
    return out


def coloured_surface(vw: VirtualWorkpiece, variable: str = "deflection", stride: int | None = None,
                     merge: bool = True):
    """The closed surface (:func:`simulate.machining.surface_mesh.surface_mesh`) with sRGB vertex
    colours of ``variable`` over :func:`colour_range` (stock surface grey); with ``merge``, flat quads
    of one colour are merged into rectangles (:func:`simulate.machining.surface_mesh.merge_flat_quads`:
    same surface and colours, a fraction of the triangles). Returns ``(SurfaceMesh, RGBA (V, 4) uint8,
    values per vertex, (lo, hi))``."""
    from .surface_mesh import merge_flat_quads, surface_mesh

    sm = surface_mesh(vw.workpiece, stride=stride)
    vals = step_values(vw, sm.vertex_step, variable)
    cols, lo, hi = _colours(vals)
    if merge:
        packed = cols.astype(np.int64) @ np.array([1 << 24, 1 << 16, 1 << 8, 1], np.int64)
        sm = merge_flat_quads(sm, packed)
        vals = step_values(vw, sm.vertex_step, variable)
        cols, _, _ = _colours(vals, lo, hi)
    return sm, cols, vals, (lo, hi)


def coloured_mesh(vw: VirtualWorkpiece, variable: str = "deflection", stride: int | None = None,
                  merge: bool = True):
    """:func:`coloured_surface` as a trimesh with its vertex colours. Returns ``(mesh, values per
    vertex, (lo, hi))``."""
    sm, cols, vals, scale = coloured_surface(vw, variable, stride, merge)
    return sm.trimesh(cols), vals, scale


def export_meshes(vw: VirtualWorkpiece, out_dir, variable: str = "deflection", max_points: int = 2_000_000,
                  stride: int | None = None):
    """Write ``surface_<variable>.ply``, ``surface_<variable>.glb`` and the colour legend
    ``surface_<variable>_legend.png``: the closed triangle surface of the part with vertex colours of
    ``variable`` (viridis over the range of the machined surface, stock surface grey), flat
    single-coloured regions merged (:func:`coloured_surface`). The GLB (written by trimesh) holds two
    nodes: ``part`` (linear vertex colours, as glTF defines them) and ``legend``, a rectangle beside
    the part textured with the legend image. Each file is written atomically. ``max_points`` is kept
    for compatibility (the mesh size is set by ``stride``, by default the smallest whose lattice has at
    most :data:`simulate.machining.surface_mesh.EXPORT_MAX_NODES` nodes). Returns the paths."""
    import io

    import trimesh
    from PIL import Image

    from identify.files import atomic_file

    from .surface_mesh import EXPORT_MAX_NODES, choose_stride

    if stride is None:
        stride = choose_stride(vw.workpiece.shape, EXPORT_MAX_NODES)
    sm, cols, _, (lo, hi) = coloured_surface(vw, variable, stride)
    png = legend_png(variable, lo, hi)
    v = sm.vertices
    bounds = np.array([v.min(axis=0), v.max(axis=0)]) if len(v) else np.zeros((2, 3))
    lv, lf, luv = _legend_quad(png, bounds)
    material = trimesh.visual.material.PBRMaterial(name="legend", baseColorTexture=Image.open(io.BytesIO(png)),
                                                   doubleSided=True, metallicFactor=0.0, roughnessFactor=1.0)
    # trimesh flips v on export (glTF's v = 0 is the image's top row)
    legend = trimesh.Trimesh(lv, lf, visual=trimesh.visual.TextureVisuals(uv=np.c_[luv[:, 0], 1.0 - luv[:, 1]],
                                                                          material=material), process=False)
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.Trimesh(v, sm.faces, vertex_colors=srgb_to_linear(cols), process=False),
                       geom_name="part", node_name="part")
    scene.add_geometry(legend, geom_name="legend", node_name="legend")
    out_dir = Path(out_dir)
    contents = {f"surface_{variable}.ply": lambda: sm.trimesh(cols).export(file_type="ply"),
                f"surface_{variable}.glb": lambda: scene.export(file_type="glb"),
                f"surface_{variable}_legend.png": lambda: png}
    paths = []
    for name, make in contents.items():
        with atomic_file(out_dir / name) as tmp:
            tmp.write_bytes(make())
        paths.append(out_dir / name)
    return paths


def render_png(vw: VirtualWorkpiece, path, variable: str = "deflection", max_pixels: int = 900) -> Path:
    """Top view of the machined surface coloured by ``variable`` (the highest machined point of
    each pixel; white: not machined), with axes in mm and a colour bar
    (:mod:`simulate.machining.raster_figure`). One pixel is one dexel spacing, or coarser so that
    the picture is at most ``max_pixels`` wide and high."""
    from .raster_figure import ColourBar, figure, save_png, top_view

    pts, vals = machined_points(vw, variable)
    factor, unit = DISPLAY_UNITS[variable]
    label = f"{variable.replace('_', ' ')} [{unit}]"
    title = f"virtual workpiece: {variable.replace('_', ' ')}"
    if not len(pts):   # nothing machined: an empty panel over the stock's outline
        from .raster_figure import Panel

        wp = vw.workpiece
        panel = Panel(np.full((200, 200, 3), 255, np.uint8),
                      (wp.lower[0] * 1e3, wp.upper[0] * 1e3, wp.lower[1] * 1e3, wp.upper[1] * 1e3))
        save_png(figure(panel, ColourBar(0.0, 1.0, label), title + " (nothing machined)"), path)
        return Path(path)
    cols, lo, hi = _colours(vals)
    span = float(np.ptp(pts[:, :2], axis=0).max())
    panel = top_view(pts, cols, max(vw.workpiece.spacing, span / max_pixels))
    save_png(figure(panel, ColourBar(lo * factor, hi * factor, label), title), path)
    return Path(path)


def render_mesh_png(vw: VirtualWorkpiece, path, variable: str = "deflection", max_nodes: int = 300_000,
                    azimuth_deg: float = -60.0, elevation_deg: float = 35.0, width_px: int = 900) -> Path:
    """Oblique view of the closed surface coloured by ``variable`` (stock surface grey), with a
    colour bar (:mod:`simulate.machining.raster_figure`).

    A coarse lattice (:func:`simulate.machining.surface_mesh.choose_stride` under ``max_nodes``)
    keeps it to some 10^5 triangles; faces turned away from the viewer are dropped and the rest
    rasterised with a z-buffer, each face flat-coloured by the mean of its vertices' values and
    Lambert-shaded from the view direction.
    """
    from .raster_figure import ColourBar, Panel, figure, raster_triangles, save_png
    from .surface_mesh import choose_stride, surface_mesh

    sm = surface_mesh(vw.workpiece, stride=choose_stride(vw.workpiece.shape, max_nodes))
    vals = step_values(vw, sm.vertex_step, variable)
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    view = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])  # towards the viewer
    right = np.array([-np.sin(az), np.cos(az), 0.0])
    up = np.cross(view, right)
    tri = sm.vertices[sm.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    facing = n @ view > 0
    tri, n = tri[facing], n[facing]
    fv = vals[sm.faces[facing]]
    cnt = np.isfinite(fv).sum(axis=1)
    with np.errstate(invalid="ignore"):
        fval = np.where(cnt > 0, np.nansum(fv, axis=1) / np.maximum(cnt, 1), np.nan)   # NaN: stock surface
    factor, unit = DISPLAY_UNITS[variable]
    cols, lo, hi = _colours(fval)
    shade = 0.35 + 0.65 * np.clip(n @ view, 0.0, 1.0)
    rgb = np.round(cols[:, :3] * shade[:, None]).astype(np.uint8)
    xy = np.stack([tri @ right, -(tri @ up)], axis=-1)     # image y grows downwards
    depth = -(tri @ view)
    if len(xy):
        lo_xy = xy.reshape(-1, 2).min(axis=0)
        span = float(np.ptp(xy.reshape(-1, 2), axis=0).max()) or 1.0
    else:
        lo_xy, span = np.zeros(2), 1.0
    scale = (width_px - 20) / span
    px = (xy - lo_xy) * scale + 10.0
    w = int(np.ceil(px[..., 0].max())) + 10 if len(px) else width_px
    h = int(np.ceil(px[..., 1].max())) + 10 if len(px) else width_px
    image = raster_triangles(px, depth, rgb, w, h)
    bar = ColourBar(lo * factor, hi * factor, f"{variable.replace('_', ' ')} [{unit}]", "grey: stock surface")
    title = f"virtual workpiece: {variable.replace('_', ' ')} (lattice {sm.pitch * 1e3:.2g} mm)"
    save_png(figure(Panel(image), bar, title), path)
    return Path(path)
