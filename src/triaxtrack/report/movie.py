"""The movie of the report: the deforming specimen seen from the side, as H.264 MP4 and as a
self-contained HTML page that plays it.

Frames are drawn with OpenCV (filled quads of the membrane grid, a video rather than a chart);
the colour bar beside them is drawn once by matplotlib. The membrane grid (which IDs are
membrane dots, where each sits on the grid) is the kit's :class:`MembraneLayout`. The workflow's
stage, from the files to the movie and its page: :func:`run_specimen_movie`.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

import av
import cv2
import numpy as np
import pandas as pd
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize, to_rgb

from triaxtrack.kit import load_kit_design
from triaxtrack.report.common import MIN_RANGE, chosen_frames, half_range
from triaxtrack.report.config import ReportConfig
from triaxtrack.report.layout import MembraneLayout, membrane_layout
from triaxtrack.report.style import DIVERGING_CMAP, MISSING, figure_image, new_figure, styled
from triaxtrack.tables import POINTS, STRAINS, read_table
from triaxtrack.video.write import CODECS, ENCODER_THREADS

if TYPE_CHECKING:
    from av.container import OutputContainer
    from av.video.stream import VideoStream

__all__ = ["DIVERGING", "specimen_frames", "write_movie", "write_movie_page"]

BGR = tuple[int, int, int]
WHITE: BGR = (255, 255, 255)
TEXT: BGR = (30, 30, 30)
AXIS: BGR = (90, 90, 90)
OTHER_TARGETS: BGR = (70, 70, 70)  # the pedestals' coded targets
FONT = cv2.FONT_HERSHEY_SIMPLEX  # ASCII only: "deg", "x3"
SMALL, TITLE = 0.4, 0.5  # font scales of the view labels and the time line


def _diverging_lut() -> np.ndarray:
    """(256, 1, 3) uint8 BGR look-up table of the report's diverging colour map."""
    rgb = DIVERGING_CMAP(np.linspace(0.0, 1.0, 256))[:, :3]
    return (rgb[:, ::-1] * 255).round().astype(np.uint8).reshape(256, 1, 3)


DIVERGING = _diverging_lut()
MISSING_BGR: BGR = tuple(int(round(255 * c)) for c in to_rgb(MISSING)[::-1])  # type: ignore[assignment]

MOVIE_TOP_PX = 34  # the time line
MOVIE_BOTTOM_PX = 26  # the view labels
COLOURBAR_PX = 100
SHADE_AMBIENT = 0.55  # a quad facing the viewer at angle a is drawn at (0.55 + 0.45 cos a) brightness
REACH_PAD = 1.04  # the views' half width: the farthest target's distance from the axis, plus 4 %


def _colours(values: np.ndarray, vmax: float) -> np.ndarray:
    """(N, 3) uint8 BGR colours of signed values on the diverging scale -vmax..vmax; NaN grey."""
    v = np.asarray(values, float)
    idx = np.clip(np.round((np.nan_to_num(v) / vmax + 1) * 127.5), 0, 255).astype(np.intp)
    out = DIVERGING[idx, 0].copy()
    out[~np.isfinite(v)] = MISSING_BGR
    return out


def _text(img: np.ndarray, text: str, org: tuple[float, float], scale: float = SMALL,
          colour: BGR = TEXT, align: str = "left") -> None:  # fmt: skip
    """Draw ``text`` with its baseline at ``org[1]``; ``align`` left / centre / right of org[0]."""
    (w, _), _ = cv2.getTextSize(text, FONT, scale, 1)
    x = org[0] - {"left": 0, "centre": w / 2, "right": w}[align]
    cv2.putText(img, text, (int(round(x)), int(round(org[1]))), FONT, scale, colour, 1, cv2.LINE_AA)


@styled
def _colour_bar(height: int, vmax: float, unit: str, factor: float) -> np.ndarray:
    """A (height, COLOURBAR_PX, 3) BGR tile: the diverging scale from -vmax to +vmax (times
    ``factor``, labelled in ``unit``) beside the movie's views, level with them."""
    fig = new_figure(COLOURBAR_PX, height, layout=None)
    bottom, top = MOVIE_BOTTOM_PX / height, MOVIE_TOP_PX / height
    cax = fig.add_axes((0.1, bottom, 0.16, 1.0 - top - bottom))
    norm = Normalize(-vmax * factor, vmax * factor)
    fig.colorbar(ScalarMappable(norm, DIVERGING_CMAP), cax=cax, extend="both")
    cax.set_ylabel(unit)
    tile = figure_image(fig)
    if tile.shape[:2] != (height, COLOURBAR_PX):  # never expected: new_figure sizes in whole pixels
        tile = cv2.resize(tile, (COLOURBAR_PX, height), interpolation=cv2.INTER_AREA)
    return tile


def _displaced(points: pd.DataFrame, magnify: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) positions of the rows of ``points``: as measured, of the same target at the first
    frame of the table (NaN where it is missing there), and as drawn, with the displacement
    from the first frame times ``magnify`` (the measured ones when ``magnify`` is 1)."""
    cols = ["x_mm", "y_mm", "z_mm"]
    xyz = points[cols].to_numpy(float)
    if points.empty:
        return xyz, xyz, xyz
    first = points[points["frame"] == points["frame"].min()].drop_duplicates("id").set_index("id")
    ref_xyz = first[cols].reindex(points["id"]).to_numpy(float)
    drawn = xyz if magnify == 1.0 else ref_xyz + magnify * (xyz - ref_xyz)
    return xyz, ref_xyz, drawn


def _rows_by_frame(points: pd.DataFrame) -> dict[int, np.ndarray]:
    """Frame -> positional row indices of ``points`` in that frame."""
    groups = pd.Series(np.arange(len(points)), index=points["frame"].to_numpy()).groupby(level=0)
    return {int(f): k.to_numpy() for f, k in groups}


@dataclass(frozen=True)
class _Stage:
    """Where the movie's views are drawn: pixels per mm and the extents, fixed for all frames."""

    scale: float  # pixels per mm
    z_lo: float
    z_hi: float
    panel_w: int
    top: int


@dataclass(frozen=True, eq=False)
class _Scene:
    """Everything fixed over the movie: the membrane dots (``mem``, their drawn positions,
    radial displacements and grid indices), the other targets, the stage and the colours."""

    layout: MembraneLayout
    corners: np.ndarray  # (n_cells, 4) the grid cells' corner dots
    drawn: np.ndarray  # (N, 3) mm, the membrane dots as drawn
    radial: np.ndarray  # (N,) mm, radial displacement from the first frame
    grid_idx: np.ndarray  # (N,) flat grid index of each membrane row
    centre: np.ndarray  # (2,) mm, the axis
    mem_frames: dict[int, np.ndarray]
    other_frames: dict[int, np.ndarray]
    strain_frames: dict[int, pd.DataFrame]
    times: pd.Series
    stage: _Stage
    bar: np.ndarray
    width: int
    height: int
    views_deg: tuple[float, ...]
    colour_by: str
    vmax: float
    magnify: float


def _stage(drawn: np.ndarray, centre: np.ndarray, height: int) -> _Stage:
    """The scale and extents that fit every drawn target of every frame into ``height``."""
    every = drawn[np.isfinite(drawn).all(axis=1)]
    reach = float(np.hypot(*(every[:, :2] - centre).T).max()) * REACH_PAD
    z_lo, z_hi = float(every[:, 2].min()), float(every[:, 2].max())
    pad = 0.03 * (z_hi - z_lo + 1.0)
    z_lo, z_hi = z_lo - pad, z_hi + pad
    scale = (height - MOVIE_TOP_PX - MOVIE_BOTTOM_PX) / (z_hi - z_lo)
    return _Stage(scale, z_lo, z_hi, int(math.ceil(2 * reach * scale)) + 20, MOVIE_TOP_PX)


def _scene(
    points: pd.DataFrame,
    layout: MembraneLayout,
    strains: pd.DataFrame | None,
    colour_by: str,
    views_deg: Sequence[float],
    height: int,
    magnify: float,
    vmax: float | None,
) -> _Scene:
    """The :class:`_Scene` of :func:`specimen_frames` (its arguments); ValueError as it says."""
    if colour_by != "radial" and (strains is None or colour_by not in strains):
        raise ValueError(f"colour_by={colour_by!r} needs a strains table with that column")
    pts = points.sort_values(["frame", "id"])
    is_mem = layout.is_membrane(pts["id"].to_numpy())
    mem, others = pts[is_mem], pts[~is_mem]
    if mem.empty:
        raise ValueError(f"no membrane dots ({layout.describe()}) in the points table")
    xyz, ref_xyz, drawn = _displaced(mem, magnify)
    centre = xyz[(mem["frame"] == mem["frame"].min()).to_numpy(), :2].mean(axis=0)  # the axis
    radial = np.hypot(*(xyz[:, :2] - centre).T) - np.hypot(*(ref_xyz[:, :2] - centre).T)
    others_drawn = _displaced(others, magnify)[2]
    if colour_by == "radial" or strains is None:  # (strains is None only with "radial": checked above)
        vmax = half_range(radial) if vmax is None else vmax
        unit, factor = "radial displacement (mm)", 1.0
        strain_frames = {}
    else:
        vmax = half_range(strains[colour_by].to_numpy(float)) if vmax is None else vmax
        unit, factor = f"{colour_by} (%)", 100.0
        strain_frames = dict(tuple(strains.groupby("frame")))
    vmax = max(float(vmax), MIN_RANGE)
    stage = _stage(np.vstack([drawn, others_drawn]), centre, height)
    bar = _colour_bar(height, vmax, unit, factor)
    width = stage.panel_w * len(views_deg) + bar.shape[1]
    return _Scene(
        layout=layout, corners=layout.cell_corners(), drawn=drawn, radial=radial,
        grid_idx=layout.grid_index(mem["id"].to_numpy()), centre=centre, mem_frames=_rows_by_frame(mem),
        other_frames={f: others_drawn[k] for f, k in _rows_by_frame(others).items()},
        strain_frames=strain_frames,
        times=pts.groupby("frame")["time_s"].first(), stage=stage, bar=bar, width=width + width % 2,
        height=height, views_deg=tuple(views_deg), colour_by=colour_by, vmax=vmax, magnify=magnify,
    )  # fmt: skip


def specimen_frames(
    points: pd.DataFrame,
    layout: MembraneLayout,
    strains: pd.DataFrame | None = None,
    *,
    colour_by: str = "radial",
    frames: Sequence[int] | None = None,
    views_deg: Sequence[float] = (0.0, 180.0),
    height: int = 720,
    magnify: float = 1.0,
    vmax: float | None = None,
) -> Iterator[np.ndarray]:
    """The deforming specimen seen from the side, one BGR frame per test frame (all of
    ``points``' frames, or those of ``frames`` that it has), all the same even size.

    Each view is an orthographic projection of the membrane along the horizontal direction
    ``(cos a, sin a, 0)`` towards the axis, for each azimuth ``a`` of ``views_deg`` (default: two
    opposite sides, so the whole membrane is seen), z up. The cells of the kit's membrane grid
    (``layout``) facing the viewer are filled quads between their four dots (a cell is left out
    while a corner dot is missing), shaded by their slant, coloured on a diverging scale by
    ``colour_by``:

    * ``"radial"``: the mean radial displacement of the cell's dots from the first frame (mm,
      outward positive) about the axis through the first frame's membrane centroid, parallel
      to z;
    * ``"e_zz"``, ``"e_tt"``, ``"e_tz"``: that local strain of ``strains`` (%, tension positive);
      grey where the frame has no value.

    Other targets of ``points`` (the pedestals' coded targets) are dark grey dots. ``magnify``
    scales the displacements from the first frame (geometry only; the colours stay true).
    ``vmax``: half the colour range (mm, or strain); default: the 99th percentile magnitude over
    the whole movie. The frame time is printed at the top left, the scale on the right.
    ``points``: a ``tables.POINTS`` table; its membrane dots are the kit's (``layout``).
    Raises ValueError (at the call, before any frame is drawn) when there is no membrane dot, or
    a strain is asked for without ``strains``.
    """
    height += height % 2  # yuv420p needs even sizes
    scene = _scene(points, layout, strains, colour_by, views_deg, height, magnify, vmax)
    wanted = sorted(scene.mem_frames) if frames is None else sorted(set(frames) & set(scene.mem_frames))
    return (_render(scene, frame) for frame in wanted)  # the checks above ran now, the drawing waits


def _cell_values(scene: _Scene, frame: int, rows: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(n_cells,) the value each cell of the grid is coloured by at ``frame`` (NaN: none)."""
    layout = scene.layout
    if scene.colour_by == "radial":
        disp = np.full(layout.n_dots, np.nan)
        disp[scene.grid_idx[rows]] = scene.radial[rows]
        return disp[corners].mean(axis=1)
    value = np.full(layout.n_cells, np.nan)
    cells = scene.strain_frames.get(frame)
    if cells is not None:
        k = layout.cell_index(cells["row"].to_numpy(), cells["col"].to_numpy())
        inside = k >= 0
        value[k[inside]] = cells[scene.colour_by].to_numpy(float)[inside]
    return value


def _render(scene: _Scene, frame: int) -> np.ndarray:
    """One frame of the movie."""
    rows = scene.mem_frames[frame]
    corners = scene.corners
    pos = np.full((scene.layout.n_dots, 3), np.nan)
    pos[scene.grid_idx[rows]] = scene.drawn[rows]
    quad = pos[corners]  # (cells, 4, 3)
    ok = np.isfinite(quad).all(axis=(1, 2))
    colours = _colours(_cell_values(scene, frame, rows, corners), scene.vmax).astype(float)
    extra = scene.other_frames.get(frame)
    img = np.full((scene.height, scene.width, 3), 255, np.uint8)
    panel_w = scene.stage.panel_w
    for v, azimuth in enumerate(scene.views_deg):
        _draw_view(img, v * panel_w, scene.stage, quad[ok], colours[ok], scene.centre, azimuth, extra)
    bar_x = panel_w * len(scene.views_deg)
    img[:, bar_x : bar_x + scene.bar.shape[1]] = scene.bar
    _text(img, f"t = {float(scene.times.get(frame, np.nan)):.2f} s   frame {frame}", (12, 22), TITLE)
    if scene.magnify != 1.0:
        _text(img, f"displacements x{scene.magnify:g}", (bar_x - 12, 22), align="right")
    return img


def _draw_view(
    img: np.ndarray,
    x_off: int,
    stage: _Stage,
    quad: np.ndarray,
    colours: np.ndarray,
    centre: np.ndarray,
    azimuth_deg: float,
    extra: np.ndarray | None,
) -> None:
    """Draw one orthographic side view into ``img`` at column ``x_off``: the quads facing the
    viewer (back to front), then the other targets in front of the axis, then the view label."""
    a = math.radians(azimuth_deg)
    toward = np.array([math.cos(a), math.sin(a)])  # from the axis to the viewer
    right = np.array([-math.sin(a), math.cos(a)])
    mid = quad.mean(axis=1)
    radial = mid[:, :2] - centre
    r = np.linalg.norm(radial, axis=1)
    facing = radial @ toward / np.maximum(r, 1e-9)
    front = np.flatnonzero(facing > 0)
    front = front[np.argsort(facing[front])]  # the slanted ones first, the nearest last
    cx = x_off + stage.panel_w / 2

    def to_px(p: np.ndarray) -> np.ndarray:
        u = (p[..., :2] - centre) @ right
        return np.stack([cx + u * stage.scale, stage.top + (stage.z_hi - p[..., 2]) * stage.scale], axis=-1)

    px = (to_px(quad[front]) * 16).round().astype(np.int32)  # 4 bits of sub-pixel precision
    shade = SHADE_AMBIENT + (1 - SHADE_AMBIENT) * facing[front]
    for poly, colour, s in zip(px, colours[front], shade, strict=True):
        cv2.fillConvexPoly(img, poly, tuple(float(c) * s for c in colour), cv2.LINE_8, shift=4)
    if extra is not None and len(extra):
        p = extra[np.isfinite(extra).all(axis=1)]
        p = p[(p[:, :2] - centre) @ toward > 0]
        for u, v in to_px(p).round().astype(int):
            cv2.circle(img, (int(u), int(v)), 3, OTHER_TARGETS, -1, cv2.LINE_AA)
    _text(img, f"seen from azimuth {azimuth_deg:g} deg", (cx, img.shape[0] - 8), SMALL, AXIS, align="centre")


def _open_stream(
    path: Path, shape: tuple[int, ...], rate: Fraction, crf: int, preset: str
) -> tuple[OutputContainer, VideoStream]:
    """An H.264 MP4 container and stream at ``path`` for frames of ``shape`` (odd sizes padded)."""
    h, w = shape[0] + shape[0] % 2, shape[1] + shape[1] % 2
    container = av.open(str(path), mode="w", options={"movflags": "+faststart"})
    stream = container.add_stream(
        CODECS["h264"],
        rate=rate,
        options={"crf": str(crf), "preset": preset, "x264-params": f"threads={ENCODER_THREADS}"},
    )
    stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
    ctx = stream.codec_context
    ctx.colorspace = ctx.color_primaries = ctx.color_trc = 6  # SMPTE 170M (BT.601)
    ctx.color_range = 1  # MPEG (limited) range, what swscale makes and players expect
    return container, stream


def write_movie(
    frames: Iterable[np.ndarray], path: str | Path, fps: float, crf: int = 23, preset: str = "medium"
) -> int:
    """Encode BGR uint8 frames (all of the first frame's shape) to an H.264 MP4 at ``path`` that
    browsers play: yuv420p (limited range, BT.601, so tagged), the index at the front of the
    file (``faststart``). An odd width or height is padded with one white column or row.
    Frame k is at time k / fps s. Returns the number of frames written; ValueError if none or if
    a frame's shape differs from the first's.

    Not :class:`triaxtrack.video.VideoWriter`: that writes grayscale frames into the luma plane
    (full range, constant chroma), made for the camera videos; this movie is in colour."""
    rate = Fraction(fps).limit_denominator(100_000)
    if rate <= 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    path = Path(path)
    opened: tuple[OutputContainer, VideoStream] | None = None
    shape: tuple[int, ...] | None = None
    n = 0
    try:
        for frame in frames:
            if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
                raise ValueError(
                    f"{path}: frames must be (H, W, 3) uint8 BGR, got {frame.dtype} {frame.shape}"
                )
            if opened is None:
                shape = frame.shape
                opened = _open_stream(path, shape, rate, crf, preset)
            elif frame.shape != shape:
                raise ValueError(f"{path}: frame {n} has shape {frame.shape}, the first {shape}")
            container, stream = opened
            pad_h, pad_w = stream.height - frame.shape[0], stream.width - frame.shape[1]
            if pad_h or pad_w:
                frame = cv2.copyMakeBorder(frame, 0, pad_h, 0, pad_w, cv2.BORDER_CONSTANT, value=WHITE)
            vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="bgr24")
            vf = vf.reformat(format="yuv420p")
            vf.pts = n
            vf.time_base = 1 / rate
            for packet in stream.encode(vf):
                container.mux(packet)
            n += 1
        if opened is None:
            raise ValueError(f"{path}: no frames to encode")
        container, stream = opened
        for packet in stream.encode(None):
            container.mux(packet)
    finally:
        if opened is not None:
            opened[0].close()
    return n


def write_movie_page(movie: str | Path, path: str | Path, title: str = "") -> None:
    """Write ``path``: a self-contained HTML page that plays the MP4 ``movie`` (embedded as a
    base64 data URI) in a looping ``<video>`` element. Snakemake's report shows HTML results in a
    frame but offers other files, an MP4 included, only as a download."""
    data = base64.b64encode(Path(movie).read_bytes()).decode("ascii")
    name = html.escape(Path(movie).name)
    heading = f"<p>{html.escape(title)}</p>\n" if title else ""
    page = (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{html.escape(title) or name}</title>\n"
        "<style>body{margin:0;font-family:sans-serif;font-size:14px}video{max-width:100%;height:auto}"
        "p{margin:6px 8px}</style>\n</head>\n<body>\n"
        f'{heading}<video controls loop muted autoplay playsinline preload="auto" '
        f'src="data:video/mp4;base64,{data}"></video>\n'
        "</body>\n</html>\n"
    )
    Path(path).write_text(page, encoding="ascii")


def run_specimen_movie(
    *,
    points: str | Path,
    strains: str | Path,
    kit: str | Path,
    movie: str | Path,
    player: str | Path,
    test: str,
    report_cfg: dict,
) -> None:
    """Rule specimen_movie: the deforming specimen of ``test`` (its ``points`` and ``strains``,
    the membrane grid of the kit folder ``kit``) at up to ``movie_max_frames`` frames spread over
    the test (:func:`specimen_frames`, coloured by ``movie_colour_by``, displacements times
    ``movie_magnify``, ``movie_height_px`` high), written as the MP4 ``movie`` at ``movie_fps``
    (:func:`write_movie`) and the HTML page ``player`` that plays it (:func:`write_movie_page`);
    prints what was written. ``report_cfg``: the config's ``report`` section (:class:`ReportConfig`)."""
    cfg = ReportConfig.from_dict(report_cfg)
    fps, colour_by, magnify = cfg.movie_fps, cfg.movie_colour_by, cfg.movie_magnify
    layout = membrane_layout(load_kit_design(kit))
    pts = read_table(points, POINTS)
    local = read_table(strains, STRAINS)
    frames = chosen_frames(pts["frame"].unique(), cfg.movie_max_frames)
    shown = specimen_frames(
        pts, layout, local, colour_by=colour_by, frames=frames, height=cfg.movie_height_px, magnify=magnify
    )
    n = write_movie(shown, movie, fps)
    write_movie_page(
        movie,
        player,
        f"test {test}: {n} frames of {pts['frame'].nunique()}, coloured by "
        f"{colour_by}, displacements x{magnify:g}",
    )
    print(f"{movie}: {n} frames at {fps} fps ({layout.describe()})")
