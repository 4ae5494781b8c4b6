"""The top cap's rigid pose from its coded targets (mm, cell frame)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from triaxtrack.kit import design_points, surface_by_name
from triaxtrack.kit_design import KitDesign


def _readonly(a: np.ndarray) -> np.ndarray:
    """A read-only copy of ``a``."""
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class TopCap:
    """Rigid pose of the top cap: ``x = rotation @ X_design + translation`` (mm).

    ``face_point`` (3,) the centre of the specimen's top face (the design face centre mapped),
    ``face_normal`` (3,) its unit normal pointing up (out of the specimen), ``height_mm`` the face
    centre's height above the bottom face z = 0, ``n_targets`` the CTs used, ``rms_mm`` their fit
    residual, ``face_sigma_mm`` the face height's standard error.
    """

    rotation: np.ndarray
    translation: np.ndarray
    face_point: np.ndarray
    face_normal: np.ndarray
    height_mm: float
    n_targets: int
    rms_mm: float
    source: str = "coded targets"  # or "membrane top rows" (:func:`top_cap_from_membrane`)
    face_sigma: float | None = None  # given where the face is not a rigid fit: see face_sigma_mm

    @property
    def face_sigma_mm(self) -> float:
        """The face height's standard error (mm): the rigid fit's residual over its degrees of
        freedom, ``rms / sqrt(3 n - 6)``, or where the face is carried up from the membrane's
        rows, that extrapolation's own (:func:`top_cap_from_membrane`)."""
        if self.face_sigma is not None:
            return float(self.face_sigma)
        return float(self.rms_mm / np.sqrt(max(3 * self.n_targets - 6, 1)))


def rigid_fit(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation R and translation t with ``dst ~ R src + t`` (Kabsch/Umeyama, no
    scale), from (n, 3) point pairs, n >= 3 not collinear."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    u, _, vt = np.linalg.svd((dst - cd).T @ (src - cs))
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, 1.0, d]) @ vt
    return rot, cd - rot @ cs


def top_cap(points: pd.DataFrame, table: pd.DataFrame, design: KitDesign) -> TopCap:
    """The top cap's rigid pose from its coded targets (surface 'pedestal_top') in one frame.

    ``points`` has columns ``id, x_mm, y_mm, z_mm`` (mm, cell frame). The specimen's top face is
    the design plane z = ``pedestal_top`` z_min (the specimen height) carried by the fitted
    transform. Raises ValueError when fewer than 3 of the cap's targets are measured.
    """
    ids = table.loc[table["surface"] == "pedestal_top", "id"]
    des = design_points(design, table).set_index("id").loc[ids, ["x_mm", "y_mm", "z_mm"]]
    meas = points.loc[points["id"].isin(ids), ["id", "x_mm", "y_mm", "z_mm"]].drop_duplicates("id")
    meas = meas[np.isfinite(meas[["x_mm", "y_mm", "z_mm"]].to_numpy(float)).all(axis=1)]
    if len(meas) < 3:
        raise ValueError(f"only {len(meas)} top-cap coded targets measured (3 needed for its pose)")
    src = des.loc[meas["id"]].to_numpy(float)
    dst = meas[["x_mm", "y_mm", "z_mm"]].to_numpy(float)
    rot, trans = rigid_fit(src, dst)
    rms = float(np.sqrt(np.mean(np.sum((src @ rot.T + trans - dst) ** 2, axis=1))))
    z_face = float(surface_by_name(design)["pedestal_top"]["z_min"])
    face = rot @ np.array([0.0, 0.0, z_face]) + trans
    normal = rot @ np.array([0.0, 0.0, 1.0])
    return TopCap(
        _readonly(rot), _readonly(trans), _readonly(face), _readonly(normal), float(face[2]), len(meas), rms
    )


MIN_CAP_COLUMNS = 8  # membrane dots measured in a row for it to carry the top cap's face up
CAP_FIT_SPAN = 0.5  # of the specimen's design height: the rows below the topmost one that do
EXTRAPOLATION_TESTS = 5  # the topmost rows the face's extrapolation is tested on


def _face_design(xy: np.ndarray, below: np.ndarray, order: int) -> np.ndarray:
    """Design matrix of the top rows' model: a dot at ``xy`` (n, 2) printed ``below`` mm under
    the face's design height (``Z <= 0``) is now at height ``c0 + c1 x + c2 y + s1 Z``, for
    ``order`` 2 ``+ s2 Z^2 + t1 x Z + t2 y Z``: at ``Z = 0`` the tilted face plane; the axial
    stretch ``dz/dZ`` and, for order 2, the tilt varying linearly with height."""
    x, y, big_z = xy[:, 0], xy[:, 1], below
    cols = [np.ones_like(x), x, y, big_z] + ([big_z**2, x * big_z, y * big_z] if order == 2 else [])
    return np.column_stack(cols)


def _face_fit(
    dots: pd.DataFrame, top: float, span: float, order: int
) -> tuple[np.ndarray, float, float, int]:
    """:func:`_face_design`'s model fitted to the ``dots`` (columns ``row, Z, x, y, z``) printed
    from ``top`` down by ``span`` (mm): its coefficients, the standard error of ``c0`` and the
    RMS residual (mm), and the dots used. ValueError with fewer than ``order + 1`` rows of
    ``MIN_CAP_COLUMNS`` dots there."""
    use = dots[(dots["Z"] <= top + 1e-9) & (dots["Z"] >= top - span)]
    if (use.groupby("row").size() >= MIN_CAP_COLUMNS).sum() < order + 1:
        raise ValueError(f"fewer than {order + 1} membrane rows measured on {MIN_CAP_COLUMNS} columns")
    a = _face_design(use[["x", "y"]].to_numpy(float), use["Z"].to_numpy(float), order)
    z = use["z"].to_numpy(float)
    coef, *_ = np.linalg.lstsq(a, z, rcond=None)
    resid = z - a @ coef
    s2 = float(resid @ resid) / max(len(z) - a.shape[1], 1)
    se = float(np.sqrt(s2 * np.linalg.pinv(a.T @ a)[0, 0]))
    return coef, se, float(np.sqrt(np.mean(resid**2))), len(z)


def top_cap_from_membrane(points: pd.DataFrame, table: pd.DataFrame, design: KitDesign) -> TopCap:
    """The top cap's face carried up from the membrane's measured rows, where its coded targets
    are in no picture (a camera ring low down). The dots of the rows printed within
    ``CAP_FIT_SPAN`` of the specimen's height below the topmost row with ``MIN_CAP_COLUMNS``
    dots measured give the current height as a function of the printed height and position
    (:func:`_face_design`, order 2 with three such rows or more: an axial strain that varies
    linearly with height, as a non-uniform compression or end restraint makes it, and a tilt);
    at the face's printed height it is the face plane. The cap is taken centred on the axis, its
    rotation the smallest that tilts z to the plane's normal.

    ``face_sigma``: the fit's standard error combined with the extrapolation's own error, tested
    on this frame: on each of the ``EXTRAPOLATION_TESTS`` topmost rows, the same model fitted to
    the rows at least as far below it as the face is above the topmost row predicts the row;
    the RMS of their mean misses is the error taken (where no row can be tested so, the strain
    over the distance, ``|Z_top| |s1 - 1|``, as large again). ``n_targets``: the dots fitted;
    ``rms_mm``: their residual. ValueError when no two rows have ``MIN_CAP_COLUMNS`` dots
    measured. On the simulated 720p test at a 260 mm ring (the top 6 rows and the cap in no
    picture) the face is within 0.018 mm of the truth at every frame, its sigma 0.001-0.016 mm.
    """
    mem = table[table["surface"] == "membrane"]
    z_face = float(surface_by_name(design)["pedestal_top"]["z_min"])
    xyz = points.dropna(subset=["x_mm", "y_mm", "z_mm"]).drop_duplicates("id").set_index("id")
    xyz = xyz.reindex(mem["id"])
    dots = pd.DataFrame({"row": mem["row"].to_numpy(), "Z": mem["z_mm"].to_numpy(float) - z_face,
                         "x": xyz["x_mm"].to_numpy(), "y": xyz["y_mm"].to_numpy(),
                         "z": xyz["z_mm"].to_numpy()}).dropna(subset=["z"])  # fmt: skip
    rows = dots.groupby("row")["Z"].agg(["size", "max"])
    full = rows.loc[rows["size"] >= MIN_CAP_COLUMNS, "max"]
    order = 2 if len(full) >= 3 else 1
    if len(full) < 2:
        raise ValueError("fewer than 3 top-cap coded targets and no two membrane rows measured on "
                         f"{MIN_CAP_COLUMNS} columns: no top cap")  # fmt: skip
    top, span = float(full.max()), CAP_FIT_SPAN * float(design.specimen.height)
    coef, se, rms, n = _face_fit(dots, top, span, order)
    misses = []
    for row_top in np.sort(full.to_numpy(float))[::-1][:EXTRAPOLATION_TESTS]:
        try:  # the same extrapolation, from as far below, tested on a measured row
            test = _face_fit(dots, row_top + top, span, order)[0]
        except ValueError:
            break
        row = dots[np.isclose(dots["Z"], row_top)]
        pred = _face_design(row[["x", "y"]].to_numpy(float), row["Z"].to_numpy(float), order) @ test
        misses.append(float(np.mean(pred - row["z"].to_numpy(float))))
    extrapolation = float(np.sqrt(np.mean(np.square(misses)))) if misses else abs(top * (coef[3] - 1.0))
    normal = np.array([-coef[1], -coef[2], 1.0]) / np.hypot(1.0, np.hypot(coef[1], coef[2]))
    axis = np.cross([0.0, 0.0, 1.0], normal)
    sin, cos = float(np.linalg.norm(axis)), float(normal[2])
    rot = np.eye(3) if sin < 1e-15 else cv2.Rodrigues(axis / sin * np.arctan2(sin, cos))[0]
    face = np.array([0.0, 0.0, coef[0]])
    trans = face - rot @ np.array([0.0, 0.0, z_face])
    pose = (_readonly(rot), _readonly(trans), _readonly(face), _readonly(normal), float(face[2]))
    return TopCap(*pose, n, rms, "membrane top rows", float(np.hypot(se, extrapolation)))
