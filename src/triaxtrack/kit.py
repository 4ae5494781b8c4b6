"""The target kit: design table (paper Table 1), printed shapes, textures and printable sheets.

Everything is derived from one design (``config/kit.yaml``, read into a
:class:`~triaxtrack.kit_design.KitDesign` by :func:`load_design`), so the printer, the
simulator and the pipeline read the same numbers. Conventions of ``target-kit.md``: cell frame,
millimetres, ``theta`` counter-clockwise from +x seen from +z; a surface is a z-axis cylinder;
texture column ``u`` covers ``theta = 2 pi (u + 0.5) / W`` and row ``v`` covers
``z = z_max - (v + 0.5) (z_max - z_min) / H``.

Printed shapes are polygons in surface coordinates ``(theta, z)``, built from each target's
local print frame ``(a, b)``: ``a`` is arc length along +theta (to the right when the surface is
seen from outside), ``b`` is up (+z); ``theta = theta_c + a / radius``, ``z = z_c + b``. The
membrane's shapes are in material coordinates of the undeformed printed surface.

Reading of Eqs. 2-3: as printed they give c = -1 for C = 1. The kit uses
``c = (C - 1) * step + first`` and ``r = (R - 1) * step + first`` with ``first = 1`` and
``step = 4`` (so C = 1 -> c = 1, the column under pedestal CT pair 1/17, C = 16 -> c = 61, and
R = 1..15 -> r = 1..57): the large dots sit in the columns directly between each pedestal CT
pair, every fourth row from the top. ``first`` and ``step`` are configurable.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from triaxtrack.codes import bits_of, code_table
from triaxtrack.kit_design import (
    BoardDesign,
    CellTargetsDesign,
    CodedTargetDesign,
    KitDesign,
    MembraneDesign,
)
from triaxtrack.kit_design import load_design as load_design
from triaxtrack.raster import equal_area_radius, polygon_coverage

DOT_VERTICES = 16  # vertices of a printed dot: an equal-area 16-gon (exact area, symmetric)
ARC_STEP_DEG = 5.0  # max angle between vertices along a code-ring arc
BAND_STEP_DEG = 1.0  # max theta between vertices along a cell band edge
BAND_PIECE_DEG = 2.0  # annular bands are drawn as pieces this wide, so back faces can be culled
LABEL_VERTICES = 48  # white label disc behind a pedestal CT
CT_CENTRE_VERTICES = 32
BAND_STEP_Z = 5.0  # max z between vertices along a longitudinal band edge, mm
SHEET_CHECK_BAR_MM = 100.0
BOARD_PNG_PX_PER_MM = 10.0

TARGET_COLUMNS = [
    "id", "kind", "surface", "theta_rad", "z_mm", "diameter_mm", "group", "large", "row", "col",
]  # fmt: skip


# ---------------------------------------------------------------- geometry of the surfaces
def membrane_radius(design: KitDesign) -> float:
    """Radius of the printed (outer) membrane surface, undeformed: soil radius + thickness."""
    s = design.specimen
    return s.diameter / 2 + s.membrane_thickness


def surfaces(design: KitDesign) -> list[dict]:
    """The four printed cylinders (undeformed positions), as ``kit.json`` lists them."""
    c, p = design.cell, design.pedestal
    h = design.specimen.height
    return [
        {"name": "membrane", "radius": membrane_radius(design), "z_min": 0.0, "z_max": h,
         "texture": "membrane.png", "medium_outside": "water"},
        {"name": "cell_outer", "radius": c.outer_radius, "z_min": c.z_min,
         "z_max": c.z_max, "texture": "cell_outer.png", "medium_outside": "air"},
        {"name": "pedestal_bottom", "radius": p.radius, "z_min": -p.height, "z_max": 0.0,
         "texture": "pedestal_bottom.png", "medium_outside": "water"},
        {"name": "pedestal_top", "radius": p.radius, "z_min": h, "z_max": h + p.height,
         "texture": "pedestal_top.png", "medium_outside": "water"},
    ]  # fmt: skip


def surface_by_name(design: KitDesign) -> dict[str, dict]:
    """:func:`surfaces` by name."""
    return {s["name"]: s for s in surfaces(design)}


# ---------------------------------------------------------------- the design table
def _pedestal_ct_rows(design: KitDesign) -> list[dict]:
    """The pedestal CTs' rows of :func:`target_table`: each stripe's CTs evenly around the
    pedestal from theta 0, ``z_from_face`` below the bottom face or above the top one (mm)."""
    h = design.specimen.height
    ped = design.pedestal_targets
    ct_diam = 2 * design.coded_target.ring_outer_radius
    rows = []
    for st in ped.stripes:
        face = 0.0 if st.surface == "pedestal_bottom" else h
        z = face - st.z_from_face if st.surface == "pedestal_bottom" else face + st.z_from_face
        for i in range(st.count):
            th = np.deg2rad(ped.theta0) + 2 * np.pi * i / st.count
            rows.append(dict(id=st.first_id + i, kind="coded", surface=st.surface, theta_rad=th, z_mm=z,
                             diameter_mm=ct_diam, group=st.name))  # fmt: skip
    return rows


def _cell_ct_theta(cell: CellTargetsDesign) -> dict[int, float]:
    """The angle (rad, cell frame, not wrapped) of every cell-wall CT by ID, as
    :func:`_cell_ct_rows` places them: the cell's dots are placed from their CT's."""
    return {
        st.first_id + i: np.deg2rad(cell.theta0) + 2 * np.pi * i / st.count
        for st in cell.ct_stripes
        for i in range(st.count)
    }


def _cell_ct_rows(design: KitDesign) -> list[dict]:
    """The cell-wall CTs' rows of :func:`target_table`: each CT stripe's CTs evenly around the
    cell from ``theta0``, at the stripe's ``z`` (mm)."""
    cell = design.cell_targets
    ct_diam = 2 * design.coded_target.ring_outer_radius
    rows = []
    for st in cell.ct_stripes:
        for i in range(st.count):
            th = np.deg2rad(cell.theta0) + 2 * np.pi * i / st.count
            rows.append(dict(id=st.first_id + i, kind="coded", surface="cell_outer", theta_rad=th,
                             z_mm=st.z, diameter_mm=ct_diam, group=st.name))  # fmt: skip
    return rows


def _cell_dot_rows(cell: CellTargetsDesign, ct_theta: dict[int, float]) -> list[dict]:
    """The cell-wall dot stripes' rows of :func:`target_table`: ``dots_per_ct`` dots from each CT's
    angle on (the first one large), ``dot_offset`` mm below its CT stripe, IDs by the paper's Eq. 1.
    ValueError for a stripe whose count is not ``dots_per_ct`` x its CT stripe's."""
    per = cell.dots_per_ct
    stripes = {s.name: s for s in cell.ct_stripes}
    rows = []
    for ds in cell.dot_stripes:
        cs = stripes[ds.ct_stripe]
        if ds.count != per * cs.count:
            raise ValueError(f"dot stripe {ds.name}: count must be {per} x its CT count")
        eq1 = per * cs.first_id - ds.first_id  # 243 for the paper's design
        step = 2 * np.pi / cs.count / per
        for i in range(cs.count):
            c_id = cs.first_id + i
            for j in range(per):
                rows.append(dict(
                    id=per * c_id - eq1 + j, kind="dot", surface="cell_outer",
                    theta_rad=ct_theta[c_id] + j * step, z_mm=cs.z - cell.dot_offset,
                    diameter_mm=cell.large_dot_diameter if j == 0 else cell.small_dot_diameter,
                    group=ds.name, large=j == 0))  # fmt: skip
    return rows


def _longitudinal_rows(cell: CellTargetsDesign, ct_theta: dict[int, float]) -> list[dict]:
    """The longitudinal stripes' rows of :func:`target_table`: each stripe's dots at its CT's angle,
    evenly from ``longitudinal_z_top`` down to ``longitudinal_z_bottom`` (mm)."""
    zt, zb = cell.longitudinal_z_top, cell.longitudinal_z_bottom
    rows = []
    for ls in cell.longitudinal_stripes:
        for i in range(ls.count):
            rows.append(dict(id=ls.first_id + i, kind="dot", surface="cell_outer",
                             theta_rad=ct_theta[ls.ct], z_mm=zt + (zb - zt) * i / (ls.count - 1),
                             diameter_mm=cell.longitudinal_dot_diameter, group=ls.name))  # fmt: skip
    return rows


def _membrane_rows(design: KitDesign) -> list[dict]:
    """The membrane grid's rows of :func:`target_table`: row r (1 at the top) and column c (1 at
    ``theta0``) at material height ``h (1 - (r - 0.5) / rows)`` mm, every ``large_step``-th row
    and column from ``large_first`` a larger dot."""
    h = design.specimen.height
    m = design.membrane
    rows = []
    for r in range(1, m.rows + 1):
        for c in range(1, m.columns + 1):
            on_grid = (r - m.large_first) % m.large_step == 0 and (c - m.large_first) % m.large_step == 0
            large = on_grid and r >= m.large_first and c >= m.large_first
            rows.append(dict(
                id=membrane_id(r, c, m), kind="dot", surface="membrane",
                theta_rad=np.deg2rad(m.theta0) + 2 * np.pi * (c - 1) / m.columns,
                z_mm=h * (1 - (r - 0.5) / m.rows),
                diameter_mm=m.large_dot_diameter if large else m.small_dot_diameter,
                group="membrane", large=large, row=r, col=c))  # fmt: skip
    return rows


def target_table(design: KitDesign) -> pd.DataFrame:
    """One row per target (paper Table 1), sorted by ID.

    Columns: ``id`` (int), ``kind`` ('coded' | 'dot'), ``surface``, ``theta_rad`` and ``z_mm``
    (centre, cell frame, undeformed; membrane in material coordinates), ``diameter_mm`` (a CT's
    outer code-ring diameter), ``group`` (stripe name), ``large`` (bool, the larger dots),
    ``row`` and ``col`` (membrane grid, 0 elsewhere).
    """
    if design.pedestal_targets.theta0 != 0:
        raise ValueError("pedestal_targets.theta0 must be 0: CT 17 defines +x of the cell frame")
    cell = design.cell_targets
    ct_theta = _cell_ct_theta(cell)
    rows = [
        *_pedestal_ct_rows(design),
        *_cell_ct_rows(design),
        *_cell_dot_rows(cell, ct_theta),
        *_longitudinal_rows(cell, ct_theta),
        *_membrane_rows(design),
    ]
    df = pd.DataFrame(rows)
    df["large"] = df["large"].fillna(False).astype(bool)
    df[["row", "col"]] = df[["row", "col"]].fillna(0).astype(np.int64)
    df["theta_rad"] = np.mod(df["theta_rad"], 2 * np.pi)
    df = df[TARGET_COLUMNS].sort_values("id").reset_index(drop=True)
    if df["id"].duplicated().any():
        dup = df.loc[df["id"].duplicated(), "id"].tolist()[:5]
        raise ValueError(f"kit design gives duplicate target IDs, e.g. {dup}")
    return df


def design_points(design: KitDesign, table: pd.DataFrame) -> pd.DataFrame:
    """Design 3-D centre of every target, undeformed: columns ``id, x_mm, y_mm, z_mm`` (cell
    frame, mm), each target on its surface's cylinder (:func:`surfaces`) at its ``theta_rad`` and
    ``z_mm``. The membrane's are on the printed surface before loading."""
    radius = {s["name"]: s["radius"] for s in surfaces(design)}
    r = table["surface"].map(radius).to_numpy(float)
    th = table["theta_rad"].to_numpy(float)
    return pd.DataFrame({
        "id": table["id"].to_numpy(np.int64),
        "x_mm": r * np.cos(th),
        "y_mm": r * np.sin(th),
        "z_mm": table["z_mm"].to_numpy(float),
    })  # fmt: skip


def membrane_id(r: int, c: int, membrane: MembraneDesign) -> int:
    """Eq. 4: ID of the membrane dot in row r, column c (1-based)."""
    return (r - 1) * membrane.columns + c + membrane.first_id - 1


def large_dot_index(C: int, R: int, membrane: MembraneDesign) -> tuple[int, int]:
    """Eqs. 2-3 as read by this kit: (c, r) of the R-th large dot under pedestal CT pair C."""
    return (C - 1) * membrane.large_step + membrane.large_first, (
        R - 1
    ) * membrane.large_step + membrane.large_first


def eq1_dot_id(ct_id: int, design: KitDesign) -> int:
    """Eq. 1: ID of the larger dot under cell CT ``ct_id`` (4 ID_CT - 243 for Table 1)."""
    cell = design.cell_targets
    per = cell.dots_per_ct
    for ds in cell.dot_stripes:
        cs = next(s for s in cell.ct_stripes if s.name == ds.ct_stripe)
        if cs.first_id <= ct_id < cs.first_id + cs.count:
            return per * ct_id - (per * cs.first_id - ds.first_id)
    raise ValueError(f"{ct_id} is not a cell CT")


def load_kit_design(kit_dir: str | Path) -> KitDesign:
    """The design back from a kit export (``kit.json`` + ``board.json``, less what the export
    adds: ``surfaces``, ``n_targets``, ``units``, ``coded_target.code_notes`` and the board's
    ``inner_corners``); ValueError naming the folder (and the section and key at fault)."""
    kit_dir = Path(kit_dir)
    try:
        kit = json.loads((kit_dir / "kit.json").read_text())
        board = json.loads((kit_dir / "board.json").read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{kit_dir}: not a readable kit export: {err}") from err
    try:
        design = {k: v for k, v in kit.items() if k not in ("surfaces", "n_targets", "units")}
        design["coded_target"] = {k: v for k, v in kit["coded_target"].items() if k != "code_notes"}
        design["board"] = {k: v for k, v in board.items() if k not in ("inner_corners", "units")}
        return KitDesign.from_dict(design)
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{kit_dir}: not a kit export: {err}") from err


def ct_codes(design: KitDesign, table: pd.DataFrame) -> dict[int, int]:
    """Code word of every coded target ID.

    A design read back from a kit export carries the printed codes (``coded_target.codes``:
    bit strings, sector 0 first); those are authoritative. A design file gets the family's codes.
    """
    ct = design.coded_target
    if ct.codes is not None:
        return {int(k): int(bits[::-1], 2) for k, bits in ct.codes.items()}
    ids = sorted(int(i) for i in table.loc[table.kind == "coded", "id"])
    return code_table(ids, ct.sectors, ct.min_distance)


# ---------------------------------------------------------------- printed shapes
@dataclass(frozen=True)
class ShapeSet:
    """Polygons printed on one surface in one layer, stacked for vectorised mapping.

    ``theta_z`` (M, 2) holds every vertex in surface coordinates (rad, mm); polygon k is
    ``theta_z[starts[k] : starts[k] + counts[k]]``; ``ids[k]`` is its target ID (-1 for bands)
    and ``center[k]`` the (theta, z) of the target centre it belongs to.
    """

    surface: str
    layer: str  # "label" (white) or "ink" (black)
    ids: np.ndarray
    starts: np.ndarray
    counts: np.ndarray
    theta_z: np.ndarray
    center: np.ndarray

    def polygons(self, xy: np.ndarray) -> list[np.ndarray]:
        """Split an (M, k) per-vertex array into the polygons."""
        return [xy[s : s + c] for s, c in zip(self.starts, self.counts, strict=True)]


def _disc(r: float, n: int = DOT_VERTICES) -> np.ndarray:
    """A disc of radius r as the regular n-gon of equal area, counter-clockwise."""
    a = 2 * np.pi * np.arange(n) / n
    return equal_area_radius(r, n) * np.c_[np.cos(a), np.sin(a)]


def _annular_sector(r0: float, r1: float, a0: float, a1: float) -> np.ndarray:
    n = max(2, int(np.ceil(np.rad2deg(a1 - a0) / ARC_STEP_DEG)) + 1)
    a = np.linspace(a0, a1, n)
    outer = r1 * np.c_[np.cos(a), np.sin(a)]
    inner = r0 * np.c_[np.cos(a[::-1]), np.sin(a[::-1])]
    return np.vstack([outer, inner])


def coded_target_polygons(word: int, ct: CodedTargetDesign) -> list[np.ndarray]:
    """Ink polygons of one CT in its print frame (a, b), mm: centre dot and code-ring runs."""
    n = ct.sectors
    bits = bits_of(word, n)
    polys = [_disc(ct.centre_radius, CT_CENTRE_VERTICES)]
    # runs of ones (cyclic) -> one annular sector each
    start = int(np.argmin(bits)) if bits.min() == 0 else 0
    order = [(start + k) % n for k in range(n)]
    run: list[int] = []
    for k in order + [None]:
        if k is not None and bits[k]:
            run.append(k)
            continue
        if run:
            a0 = 2 * np.pi * run[0] / n
            polys.append(_annular_sector(ct.ring_inner_radius, ct.ring_outer_radius, a0,
                                         a0 + 2 * np.pi * len(run) / n))  # fmt: skip
            run = []
    return polys


def _stack(surface, layer, items) -> ShapeSet:
    ids = np.array([i for i, _, _ in items], dtype=np.int64)
    polys = [p for _, p, _ in items]
    counts = np.array([len(p) for p in polys], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    tz = np.vstack(polys) if polys else np.zeros((0, 2))
    center = np.array([c for _, _, c in items]).reshape(-1, 2)
    return ShapeSet(surface, layer, ids, starts, counts, tz, center)


def printed_shapes(design: KitDesign, table: pd.DataFrame | None = None) -> list[ShapeSet]:
    """Every printed polygon of the kit, grouped by (surface, layer); labels before ink."""
    table = target_table(design) if table is None else table
    surf = surface_by_name(design)
    codes = ct_codes(design, table)
    ct = design.coded_target
    groups: dict[tuple[str, str], list] = {}

    def add(surface, layer, tid, ab_polys, th_c, z_c):
        rad = surf[surface]["radius"]
        for ab in ab_polys:
            tz = np.c_[th_c + ab[:, 0] / rad, z_c + ab[:, 1]]
            groups.setdefault((surface, layer), []).append((tid, tz, (th_c, z_c)))

    for row in table.itertuples(index=False):
        if row.kind == "coded":
            if row.surface != "cell_outer":  # the cell's CTs sit on the white band
                add(
                    row.surface,
                    "label",
                    row.id,
                    [_disc(ct.label_radius, LABEL_VERTICES)],
                    row.theta_rad,
                    row.z_mm,
                )
            add(row.surface, "ink", row.id, coded_target_polygons(codes[row.id], ct), row.theta_rad, row.z_mm)
        else:
            add(row.surface, "ink", row.id, [_disc(row.diameter_mm / 2)], row.theta_rad, row.z_mm)
    for tz in cell_bands(design, table):
        groups.setdefault(("cell_outer", "label"), []).append((-1, tz, tuple(tz.mean(axis=0))))
    order = [(s["name"], layer) for s in surfaces(design) for layer in ("label", "ink")]
    return [_stack(s, layer, groups[(s, layer)]) for s, layer in order if (s, layer) in groups]


def cell_bands(design: KitDesign, table: pd.DataFrame) -> list[np.ndarray]:
    """White label bands on the cell (theta, z) polygons: annular bands split in short pieces."""
    cell, ct = design.cell_targets, design.coded_target
    m = cell.band_margin
    out = []
    for cs in cell.ct_stripes:
        top = cs.z + ct.ring_outer_radius + m
        bottom = cs.z - cell.dot_offset - cell.large_dot_diameter / 2 - m
        n = int(np.ceil(360 / BAND_PIECE_DEG))
        per_piece = int(np.ceil(BAND_PIECE_DEG / BAND_STEP_DEG)) + 1
        for k in range(n):
            t = np.linspace(2 * np.pi * k / n, 2 * np.pi * (k + 1) / n, per_piece)
            out.append(
                np.vstack([np.c_[t, np.full(per_piece, bottom)], np.c_[t[::-1], np.full(per_piece, top)]])
            )
    rad = design.cell.outer_radius
    half = cell.longitudinal_band_width / 2 / rad
    d = cell.longitudinal_dot_diameter / 2 + m
    for ls in cell.longitudinal_stripes:
        th = float(table.loc[table.id == ls.ct, "theta_rad"].iloc[0])
        z0, z1 = cell.longitudinal_z_bottom - d, cell.longitudinal_z_top + d
        n = int(np.ceil((z1 - z0) / BAND_STEP_Z))
        for k in range(n):
            za, zb = z0 + (z1 - z0) * k / n, z0 + (z1 - z0) * (k + 1) / n
            out.append(np.array([[th - half, za], [th + half, za], [th + half, zb], [th - half, zb]]))
    return out


# ---------------------------------------------------------------- textures and export
def texture_size(surface: dict, px_per_mm: float) -> tuple[int, int]:
    """(width, height) in texels of a surface's texture."""
    w = int(round(2 * np.pi * surface["radius"] * px_per_mm))
    h = int(round((surface["z_max"] - surface["z_min"]) * px_per_mm))
    return w, h


def theta_z_to_texel(tz: np.ndarray, surface: dict, size: tuple[int, int]) -> np.ndarray:
    """(M, 2) texel coordinates (u, v), texel centres at integers, of (theta, z) points."""
    w, h = size
    u = tz[:, 0] * w / (2 * np.pi) - 0.5
    v = (surface["z_max"] - tz[:, 1]) * h / (surface["z_max"] - surface["z_min"]) - 0.5
    return np.c_[u, v]


def render_texture(design: KitDesign, surface_name: str, shapes: list[ShapeSet] | None = None) -> np.ndarray:
    """RGBA uint8 texture of one surface: white labels and black ink, alpha 0 where bare."""
    shapes = printed_shapes(design) if shapes is None else shapes
    surface = surface_by_name(design)[surface_name]
    size = texture_size(surface, design.texture_px_per_mm)
    w, h = size
    cov = {}
    for layer in ("label", "ink"):
        polys = []
        for s in shapes:
            if s.surface != surface_name or s.layer != layer:
                continue
            uv = theta_z_to_texel(s.theta_z, surface, size)
            for p in s.polygons(uv):
                polys.append(p)
                if p[:, 0].min() < 0.5:  # wrap around theta = 0
                    polys.append(p + [w, 0])
                if p[:, 0].max() > w - 1.5:
                    polys.append(p - [w, 0])
        cov[layer] = polygon_coverage(polys, h, w)
    lab, ink = cov["label"], cov["ink"]
    alpha = lab + ink - lab * ink
    with np.errstate(invalid="ignore", divide="ignore"):
        grey = np.where(alpha > 0, 255.0 * lab * (1 - ink) / alpha, 0.0)
    rgba = np.zeros((h, w, 4), np.uint8)
    rgba[..., :3] = np.round(grey)[..., None].astype(np.uint8)
    rgba[..., 3] = np.round(255 * alpha).astype(np.uint8)
    return rgba


def board_corners_mm(board: BoardDesign) -> np.ndarray:
    """(N, 3) inner-corner positions of the checkerboard in its own plane (z = 0), mm.

    Row-major from the top-left inner corner, as OpenCV's ``findChessboardCorners`` orders them
    for a board of ``(squares_x - 1, squares_y - 1)`` inner corners.
    """
    nx, ny, s = board.squares_x - 1, board.squares_y - 1, board.square_mm
    gx, gy = np.meshgrid(np.arange(1, nx + 1) * s, np.arange(1, ny + 1) * s)
    return np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]


def board_polygons_mm(board: BoardDesign, subdivide: int = 1) -> tuple[np.ndarray, list[np.ndarray]]:
    """The board's white sheet and its black squares as (x, y) polygons in mm.

    The board frame has its origin at the outer corner of the top-left square, x to the right,
    y down the board; the sheet extends ``margin_mm`` beyond the squares.
    """
    s, m = board.square_mm, board.margin_mm
    wx, wy = board.squares_x * s, board.squares_y * s

    def rect(x0, y0, x1, y1):
        t = np.linspace(0, 1, subdivide + 1)[:-1]
        return np.vstack([np.c_[x0 + (x1 - x0) * t, np.full_like(t, y0)],
                          np.c_[np.full_like(t, x1), y0 + (y1 - y0) * t],
                          np.c_[x1 - (x1 - x0) * t, np.full_like(t, y1)],
                          np.c_[np.full_like(t, x0), y1 - (y1 - y0) * t]])  # fmt: skip

    sheet = rect(-m, -m, wx + m, wy + m)
    squares = [rect(i * s, j * s, (i + 1) * s, (j + 1) * s)
               for j in range(board.squares_y) for i in range(board.squares_x)
               if (i + j) % 2 == 0]  # fmt: skip
    return sheet, squares


def _svg_sheet(width_mm: float, height_mm: float, polys_black, polys_white, title: str) -> str:
    def path(p):
        return "M" + " L".join(f"{x:.4f},{y:.4f}" for x, y in p) + " Z"

    bar_y = height_mm + 8
    total_h = height_mm + 16
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width_mm:.3f}mm" height="{total_h:.3f}mm" '
        f'viewBox="0 0 {width_mm:.4f} {total_h:.4f}">',
        f"<title>{title}</title>",
        f'<rect x="0" y="0" width="{width_mm:.4f}" height="{height_mm:.4f}" fill="none" '
        'stroke="#aaa" stroke-width="0.1"/>',
    ]
    if polys_white:
        parts.append('<path fill="#fff" stroke="none" d="' + " ".join(path(p) for p in polys_white) + '"/>')
    if polys_black:
        parts.append('<path fill="#000" stroke="none" d="' + " ".join(path(p) for p in polys_black) + '"/>')
    parts.append(f'<rect x="5" y="{bar_y:.2f}" width="{SHEET_CHECK_BAR_MM}" height="2" fill="#000"/>')
    parts.append(f'<text x="{10 + SHEET_CHECK_BAR_MM:.1f}" y="{bar_y + 2:.2f}" font-size="3">'
                 f"check bar: 100 mm when printed at 100 % -- {title}</text>")  # fmt: skip
    parts.append("</svg>")
    return "\n".join(parts)


def export_kit(design: KitDesign, out_dir: str | Path) -> None:
    """Write the kit export of ``target-kit.md`` to ``out_dir`` (created; files overwritten)."""
    out = Path(out_dir)
    (out / "sheets").mkdir(parents=True, exist_ok=True)
    table = target_table(design)
    shapes = printed_shapes(design, table)
    codes = ct_codes(design, table)
    doc = design.to_dict()  # the sections as the design file writes them
    surf = surfaces(design)
    ppm = design.texture_px_per_mm
    kit = {
        "version": 1,
        "units": "mm",
        "specimen": doc["specimen"],
        "cell": doc["cell"],
        "water": doc["water"],
        "pedestal": doc["pedestal"],
        "surfaces": [dict(s, texture_size=list(texture_size(s, ppm))) for s in surf],
        "texture_px_per_mm": ppm,
        "coded_target": dict(
            doc["coded_target"],
            codes={
                str(k): format(v, f"0{design.coded_target.sectors}b")[::-1] for k, v in sorted(codes.items())
            },
            code_notes="bit string, sector 0 first; sector k spans "
            "[2 pi k / n, 2 pi (k+1) / n) counter-clockwise from +theta "
            "seen from outside; '1' is black",
        ),  # fmt: skip
        "membrane": doc["membrane"],
        "cell_targets": doc["cell_targets"],
        "pedestal_targets": doc["pedestal_targets"],
        "n_targets": int(len(table)),
    }
    (out / "kit.json").write_text(json.dumps(kit, indent=2))
    table.to_csv(out / "targets.csv", index=False, float_format="%.9g")
    for s in surf:
        rgba = render_texture(design, s["name"], shapes)
        cv2.imwrite(str(out / s["texture"]), cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))
        black: list[np.ndarray] = []
        white: list[np.ndarray] = []
        width = 2 * np.pi * s["radius"]
        for sh in shapes:
            if sh.surface != s["name"]:
                continue
            ab = np.c_[sh.theta_z[:, 0] * s["radius"], s["z_max"] - sh.theta_z[:, 1]]
            for poly in sh.polygons(ab):  # shapes across theta = 0 are printed at both ends
                copies = [poly] + [
                    poly + [k * width, 0]
                    for k in (-1, 1)
                    if (poly[:, 0] + k * width).min() < width and (poly[:, 0] + k * width).max() > 0
                ]
                (white if sh.layer == "label" else black).extend(copies)
        (out / "sheets" / f"{s['name']}.svg").write_text(
            _svg_sheet(width, s["z_max"] - s["z_min"], black, white, f"triaxtrack kit: {s['name']}")
        )
    board = design.board
    sheet, squares = board_polygons_mm(board)
    offset = np.array([board.margin_mm, board.margin_mm])
    (out / "board.json").write_text(json.dumps(dict(doc["board"], inner_corners=[
        board.squares_x - 1, board.squares_y - 1], units="mm"), indent=2))  # fmt: skip
    sheet_w, sheet_h = np.ptp(sheet, axis=0)
    (out / "sheets" / "board.svg").write_text(
        _svg_sheet(sheet_w, sheet_h, [q + offset for q in squares], [], "calibration board")
    )
    bpx = BOARD_PNG_PX_PER_MM
    bw, bh = int(round(sheet_w * bpx)), int(round(sheet_h * bpx))
    cov = polygon_coverage([(q + offset) * bpx - 0.5 for q in squares], bh, bw)
    cv2.imwrite(str(out / "board.png"), np.round(255 * (1 - cov)).astype(np.uint8))
    shutil.copy(Path(__file__).with_name("KIT_README.md"), out / "README.md")
