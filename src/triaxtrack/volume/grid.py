"""The membrane dot grid of one frame, and the fill of its missing dots.

Positions in mm in the cell frame (origin the centre of the bottom pedestal's top face, +z up
the axis), design theta in rad, design z in mm (material coordinates of the printed dots).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.sparse as sp
from scipy.ndimage import label
from scipy.sparse.linalg import splu

from triaxtrack.kit_design import KitDesign
from triaxtrack.volume.cap import TopCap, _readonly

MAX_MISSING_SHARE = 0.6  # default: above this share of missing dots a frame is not measured (NaN)
WARN_MISSING_SHARE = 0.2  # default: above this share a measured frame carries a warning
CENTRE_MIN_SHARE = 0.5  # a row's own circle centre needs this share of its dots measured
STRETCH_MIN_PAIRS = 8  # column pairs of measured neighbours that estimate an end's axial stretch


@dataclass(frozen=True)
class MembraneGrid:
    """One frame's membrane dots on the kit's grid.

    ``xyz`` (R, C, 3) positions in mm (cell frame) on the printed surface, index ``[i, j]`` the
    i-th row from the bottom (increasing design z) and j-th column (increasing theta);
    ``measured`` (R, C) whether the dot was measured (else filled, see :func:`membrane_grid`);
    ``theta`` (C,) design theta (rad) and ``z`` (R,) design z (mm) of the columns and rows;
    ``rows``/``cols`` the kit's 1-based row and column numbers per index (row 1 is the top row);
    ``sigma_mm`` (R, C) the measured dots' position standard error (``sigma_mm`` of
    points.parquet, mm, NaN where filled or not given) or None when the points have none.
    """

    xyz: np.ndarray
    measured: np.ndarray
    theta: np.ndarray
    z: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    sigma_mm: np.ndarray | None = None

    @property
    def filled(self) -> int:
        """Number of dots filled from their neighbours."""
        return int((~self.measured).sum())


def _membrane_layout(table: pd.DataFrame) -> tuple[pd.DataFrame, pd.Series, pd.Series]:
    """Membrane rows of the design table with grid indices ``i, j`` added; design z (mm) by
    row and theta (rad) by column, as Series indexed by the kit's row and column numbers."""
    mem = table.loc[table["surface"] == "membrane", ["id", "theta_rad", "z_mm", "row", "col"]].copy()
    if mem.empty:
        raise ValueError("the target table has no membrane dots")
    z_of_row = mem.groupby("row")["z_mm"].first().sort_values()
    th_of_col = mem.groupby("col")["theta_rad"].first().sort_values()
    if len(z_of_row) * len(th_of_col) != len(mem):
        raise ValueError("the membrane dots of the target table do not form a full grid")
    mem["i"] = mem["row"].map({r: k for k, r in enumerate(z_of_row.index)})
    mem["j"] = mem["col"].map({c: k for k, c in enumerate(th_of_col.index)})
    return mem, z_of_row, th_of_col


def grid_ids(table: pd.DataFrame) -> np.ndarray:
    """(R, C) the kit's membrane dot ID at each index of :class:`MembraneGrid`."""
    mem, z_of_row, th_of_col = _membrane_layout(table)
    ids = np.zeros((len(z_of_row), len(th_of_col)), np.int64)
    ids[mem["i"].to_numpy(), mem["j"].to_numpy()] = mem["id"].to_numpy(np.int64)
    return ids


def kasa_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Algebraic least-squares circle through (n, 2) points: centre (2,) and radius, mm."""
    a = np.c_[2 * xy, np.ones(len(xy))]
    b = (xy**2).sum(axis=1)
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    centre = sol[:2]
    return centre, float(np.sqrt(max(sol[2] + centre @ centre, 0.0)))


@dataclass(frozen=True)
class FaceEnds:
    """Where the membrane meets the two pedestal faces: the boundary rings of the fill.

    The membrane is clamped on the pedestals, whose radius is the soil's (``soil_radius_mm``):
    at the bottom face (design z 0, the cell frame's plane z = 0) its printed surface lies at
    radius ``soil_radius_mm + t`` about the cell axis, at the top face (design z ``z_top_mm``) at
    the same radius in the top cap's frame (``cap``; None: no top ring). ``t = t0_mm /
    lambda_z`` (incompressible rubber; no hoop stretch on a rigid pedestal), ``lambda_z`` the
    axial stretch of the measured dots nearest that face.
    """

    soil_radius_mm: float
    t0_mm: float
    z_top_mm: float
    cap: TopCap | None


def face_ends(design: KitDesign, cap: TopCap | None, t0: float | None = None) -> FaceEnds:
    """:class:`FaceEnds` from the kit design (specimen diameter, height and membrane thickness;
    ``t0`` in mm overrides the thickness) and the frame's top cap pose (None if unknown)."""
    spec = design.specimen
    t0 = float(spec.membrane_thickness) if t0 is None else float(t0)
    return FaceEnds(float(spec.diameter) / 2, t0, float(spec.height), cap)


def membrane_grid(
    points: pd.DataFrame,
    table: pd.DataFrame,
    max_missing_share: float = MAX_MISSING_SHARE,
    ends: FaceEnds | None = None,
) -> MembraneGrid:
    """The membrane dots of ONE frame on the kit's grid, missing dots filled.

    ``points`` has columns ``id, x_mm, y_mm, z_mm`` (mm, cell frame) and optionally
    ``sigma_mm`` (other columns and non-membrane IDs are ignored; rows with a NaN coordinate
    count as missing). Missing dots -- single dots, patches, whole columns or end rows -- are
    filled by :func:`fill_grid` from this frame's measured dots only (and the pedestal faces,
    ``ends``; without them the end rows are extrapolated). Raises ValueError when more than
    ``max_missing_share`` of the dots are missing, when an ID appears twice or when the fill
    is singular.
    """
    mem, z_of_row, th_of_col = _membrane_layout(table)
    n_r, n_c = len(z_of_row), len(th_of_col)
    cols = ["id", "x_mm", "y_mm", "z_mm"] + (["sigma_mm"] if "sigma_mm" in points.columns else [])
    pts = points.loc[points["id"].isin(mem["id"]), cols]
    pts = pts[np.isfinite(pts[["x_mm", "y_mm", "z_mm"]].to_numpy(float)).all(axis=1)]
    if pts["id"].duplicated().any():
        dup = pts.loc[pts["id"].duplicated(), "id"].tolist()[:5]
        raise ValueError(f"membrane dots measured twice in one frame, e.g. IDs {dup}")
    ij = mem.set_index("id").loc[pts["id"], ["i", "j"]].to_numpy()
    xyz = np.full((n_r, n_c, 3), np.nan)
    xyz[ij[:, 0], ij[:, 1]] = pts[["x_mm", "y_mm", "z_mm"]].to_numpy(float)
    sigma = None
    if "sigma_mm" in pts.columns:
        sigma = np.full((n_r, n_c), np.nan)
        sigma[ij[:, 0], ij[:, 1]] = pts["sigma_mm"].to_numpy(float)
    measured = np.isfinite(xyz[..., 0])
    missing_share = 1 - measured.mean()
    if missing_share > max_missing_share:
        raise ValueError(
            f"{missing_share:.1%} of the {n_r * n_c} membrane dots are missing "
            f"(more than the allowed {max_missing_share:.0%})"
        )
    theta = th_of_col.to_numpy(float)
    z = z_of_row.to_numpy(float)
    if not measured.all():
        xyz = fill_grid(xyz, measured, theta, z, ends)
    return MembraneGrid(
        _readonly(xyz), _readonly(measured), _readonly(theta), _readonly(z),
        _readonly(z_of_row.index.to_numpy(np.int64)), _readonly(th_of_col.index.to_numpy(np.int64)),
        None if sigma is None else _readonly(sigma),
    )  # fmt: skip


# ---------------------------------------------------------------- the fill
def _end_stretch(xyz: np.ndarray, measured: np.ndarray, z: np.ndarray, top: bool) -> float:
    """Median axial stretch |dx/dZ| of the measured column neighbours nearest one end (1 when
    fewer than STRETCH_MIN_PAIRS pairs exist anywhere)."""
    both = measured[1:] & measured[:-1]  # (R - 1, C) pairs of rows k, k + 1
    order = range(len(z) - 2, -1, -1) if top else range(len(z) - 1)
    for k in order:
        if both[k].sum() >= STRETCH_MIN_PAIRS:
            d = np.linalg.norm(xyz[k + 1, both[k]] - xyz[k, both[k]], axis=-1)
            return float(np.median(d) / (z[k + 1] - z[k]))
    return 1.0


def _end_rings(
    xyz: np.ndarray, measured: np.ndarray, theta: np.ndarray, z: np.ndarray, ends: FaceEnds
) -> tuple[list[np.ndarray], list[float], list[np.ndarray], int]:
    """Boundary rings (C, 3) at the faces with their design z and ring centres (2,); the number
    of rings below the dot rows (0 or 1)."""
    ring = np.c_[np.cos(theta), np.sin(theta), np.zeros(len(theta))]
    t_b = ends.t0_mm / _end_stretch(xyz, measured, z, top=False)
    rings, zs, centres = [(ends.soil_radius_mm + t_b) * ring], [0.0], [np.zeros(2)]
    if ends.cap is not None:
        t_t = ends.t0_mm / _end_stretch(xyz, measured, z, top=True)
        local = (ends.soil_radius_mm + t_t) * ring + np.array([0.0, 0.0, ends.z_top_mm])
        rings.append(local @ np.asarray(ends.cap.rotation).T + np.asarray(ends.cap.translation))
        zs.append(ends.z_top_mm)
        centres.append(np.asarray(ends.cap.face_point)[:2])
    return rings, zs, centres, 1


def _thin_plate(z_nodes: np.ndarray, n_c: int, h_theta: float) -> sp.csr_matrix:
    """Second differences of a periodic (Rn, C) node field stored row-major: theta-theta at every
    row, z-z at the inner rows (uneven spacing), sqrt(2) x the mixed one per cell. The sum of
    their squares is the thin-plate bending energy on the (arc length, design z) grid, mm."""
    rn = len(z_nodes)
    idx = np.arange(rn * n_c).reshape(rn, n_c)
    jp = np.roll(idx, -1, axis=1)
    jm = np.roll(idx, 1, axis=1)
    blocks = []  # (columns (n, k), weights (n, k)) per block of equations

    w = np.ones((rn * n_c, 1)) / h_theta**2
    blocks.append((np.stack([jm.ravel(), idx.ravel(), jp.ravel()], 1), np.hstack([w, -2 * w, w])))
    h1 = np.diff(z_nodes)[:-1][:, None] * np.ones((1, n_c))
    h2 = np.diff(z_nodes)[1:][:, None] * np.ones((1, n_c))
    a, c = (2 / (h1 * (h1 + h2))).ravel(), (2 / (h2 * (h1 + h2))).ravel()
    blocks.append((np.stack([idx[:-2].ravel(), idx[1:-1].ravel(), idx[2:].ravel()], 1),
                   np.stack([a, -(a + c), c], 1)))  # fmt: skip
    wm = (np.sqrt(2) / (h_theta * np.diff(z_nodes)))[:, None] * np.ones((1, n_c))
    wm = wm.ravel()
    blocks.append((np.stack([jp[1:].ravel(), idx[1:].ravel(), jp[:-1].ravel(), idx[:-1].ravel()], 1),
                   np.stack([wm, -wm, -wm, wm], 1)))  # fmt: skip
    rows, cols, vals, n = [], [], [], 0
    for c_, v_ in blocks:
        rows.append(np.repeat(np.arange(n, n + len(c_)), c_.shape[1]))
        cols.append(c_.ravel())
        vals.append(v_.ravel())
        n += len(c_)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, rn * n_c))  # fmt: skip


def fill_grid(
    xyz: np.ndarray, measured: np.ndarray, theta: np.ndarray, z: np.ndarray, ends: FaceEnds | None
) -> np.ndarray:
    """A copy of ``xyz`` (R, C, 3), mm, with the dots where ``measured`` (R, C) is False filled.

    Each row gets an axis centre: the least-squares circle centre of its measured dots when at
    least CENTRE_MIN_SHARE of them are measured, else linear in design z between those rows and
    the face rings (the pedestal centre at z = 0, the top face centre). About these centres each
    dot is (r, psi = azimuth - design theta, z): fields smooth in design coordinates even across a
    wide gap (a circle's Cartesian coordinates are not). The missing values minimise the
    thin-plate bending energy (:func:`_thin_plate`) of the three fields on the grid of design
    arc length and design z, periodic in theta, with the measured dots and the face rings
    (:class:`FaceEnds`) held: a natural cubic spline along a column with a gap, a smooth
    surface over a patch, C1-continuous with its surroundings. Linear in the measured values and
    computed from this frame's dots only. Raises ValueError when the fill is singular.
    """
    n_r, n_c = measured.shape
    xyz = np.asarray(xyz, float)
    if not measured.any():
        raise ValueError("no membrane dot measured")
    rings, zs, centres, below = ([], [], [], 0) if ends is None else _end_rings(xyz, measured, theta, z, ends)
    nodes = np.concatenate([rings[0][None], xyz] + [r[None] for r in rings[1:]]) if rings else xyz.copy()
    known = np.concatenate([np.ones((below, n_c), bool), measured, np.ones((len(rings) - below, n_c), bool)])
    z_nodes = np.concatenate([zs[:below], z, zs[below:]])
    # axis centre per node row
    centre = np.full((len(z_nodes), 2), np.nan)
    for k in range(n_r):
        m = measured[k]
        if m.mean() >= CENTRE_MIN_SHARE:
            centre[below + k] = kasa_circle(xyz[k, m, :2])[0]
    if rings:  # the pedestal centre below, the top face centre above
        centre[0] = centres[0]
        if len(rings) == 2:
            centre[-1] = centres[1]
    ok = np.isfinite(centre[:, 0])
    if not ok.any():
        centre[:] = kasa_circle(xyz[measured][:, :2])[0] if measured.sum() >= 3 else 0.0
    else:
        for d in range(2):
            centre[:, d] = np.interp(z_nodes, z_nodes[ok], centre[ok, d])
    rel = nodes[..., :2] - centre[:, None, :]
    r = np.hypot(rel[..., 0], rel[..., 1])
    psi = np.angle(np.exp(1j * (np.arctan2(rel[..., 1], rel[..., 0]) - theta)))
    fields = np.stack([r, psi, nodes[..., 2]], -1).reshape(-1, 3)
    h_theta = float(np.median(r[known])) * 2 * np.pi / n_c
    op = _thin_plate(z_nodes, n_c, h_theta)
    kn = known.ravel()
    a_u, a_k = op[:, ~kn], op[:, kn]
    try:
        lu = splu((a_u.T @ a_u).tocsc())
        fields[~kn] = lu.solve(-(a_u.T @ (a_k @ fields[kn])))
    except RuntimeError as err:  # scipy: "Factor is exactly singular"
        raise ValueError(f"the membrane fill is singular: {err}") from err
    if not np.all(np.isfinite(fields)):
        raise ValueError("the membrane fill is singular (too few measured rows)")
    f = fields.reshape(len(z_nodes), n_c, 3)
    ang = theta + f[..., 1]
    x = centre[:, None, 0] + f[..., 0] * np.cos(ang)
    y = centre[:, None, 1] + f[..., 0] * np.sin(ang)
    out = np.stack([x, y, f[..., 2]], -1)[below : below + n_r]
    out[measured] = xyz[measured]
    return out


def gap_labels(missing: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected gaps of an (R, C) missing mask (8-neighbours, periodic in the columns): labels
    (R, C) int, 0 where measured, 1..n per gap; and n."""
    lab, n = label(missing, structure=np.ones((3, 3), int))
    parent = np.arange(n + 1)

    def root(a: int) -> int:
        while parent[a] != a:
            a = parent[a]
        return a

    n_r = missing.shape[0]
    for k in range(n_r):
        for k2 in range(max(k - 1, 0), min(k + 2, n_r)):
            a, b = lab[k, -1], lab[k2, 0]
            if a and b and root(a) != root(b):
                parent[root(a)] = root(b)
    roots = np.array([root(a) for a in range(n + 1)])
    uniq, new = np.unique(roots, return_inverse=True)
    return new[lab].astype(np.int64), len(uniq) - 1
