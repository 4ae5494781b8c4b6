"""Local strains over the middle of the specimen, from every measured membrane dot there.

A local displacement transducer on a triaxial specimen measures over a gauge length in its
middle third, free of the bedding errors at the two ends. The same from the dots: the membrane
dots whose reference-frame height lies in the middle ``LOCAL_ZONE`` of the reference height,
measured (not filled) in both frames, give

* the **local axial strain** ``1 - b``, where ``b`` is the least-squares slope of the dots'
  heights against their reference heights, ``z = a + b z0`` (a rigid shift ``a`` of the zone
  is not a strain);
* the **local radial strain** ``1 - c``, where ``c`` is the least-squares ratio of their
  distances from the zone's axis to those in the reference, ``r = c r0`` (the axis: each
  frame's least-squares circle centre of the zone's dots, so that a sideways shift of the
  zone is not a strain).

Both compression positive, as the specimen strains of :data:`triaxtrack.tables.VOLUME`. Each
comes with its standard error from the fit's own residual scatter (the dots' noise and the
membrane's departures from a uniform stretch over the zone). Positions in mm, cell frame.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from triaxtrack.volume.grid import kasa_circle

LOCAL_ZONE = (1 / 3, 2 / 3)  # the gauge zone: this share of the reference height, from the bottom face
MIN_LOCAL_DOTS = 20  # fewer dots in the zone in both frames: no local strain (NaN)
LOCAL_COLUMNS = ("local_axial_strain", "local_axial_sigma", "local_radial_strain", "local_radial_sigma")


def _slope(x: np.ndarray, y: np.ndarray, through_origin: bool) -> tuple[float, float]:
    """Least-squares slope of ``y`` on ``x`` (with an intercept unless ``through_origin``) and its
    standard error from the residuals."""
    if through_origin:
        sxx = float(x @ x)
        b = float(x @ y) / sxx
        res = y - b * x
        dof = len(x) - 1
    else:
        xc = x - x.mean()
        sxx = float(xc @ xc)
        b = float(xc @ (y - y.mean())) / sxx
        res = y - y.mean() - b * xc
        dof = len(x) - 2
    return b, float(np.sqrt(res @ res / max(dof, 1) / sxx))


def local_strains(points: pd.DataFrame, reference: pd.DataFrame, height0_mm: float, membrane_ids) -> dict:
    """Local axial and radial strains (and their standard errors) of one frame's ``points``
    against the ``reference`` frame's (columns ``id, x_mm, y_mm, z_mm``; the measured membrane
    dots are those of ``membrane_ids`` with finite positions), over the middle ``LOCAL_ZONE`` of
    the reference height ``height0_mm``. Returns the ``LOCAL_COLUMNS`` (NaN with fewer than
    ``MIN_LOCAL_DOTS`` dots)."""
    nan = dict.fromkeys(LOCAL_COLUMNS, float("nan"))
    cols = ["id", "x_mm", "y_mm", "z_mm"]
    ref = reference.loc[reference["id"].isin(membrane_ids), cols].dropna()
    lo, hi = (f * height0_mm for f in LOCAL_ZONE)
    ref = ref[(ref["z_mm"] >= lo) & (ref["z_mm"] <= hi)]
    cur = points.loc[points["id"].isin(ref["id"]), cols].dropna()
    both = ref.merge(cur, on="id", suffixes=("_0", ""))
    if len(both) < MIN_LOCAL_DOTS or not np.isfinite(height0_mm) or height0_mm <= 0:
        return nan
    b, sb = _slope(both["z_mm_0"].to_numpy(), both["z_mm"].to_numpy(), through_origin=False)
    xy0 = both[["x_mm_0", "y_mm_0"]].to_numpy()
    xy = both[["x_mm", "y_mm"]].to_numpy()
    r0 = np.linalg.norm(xy0 - kasa_circle(xy0)[0], axis=1)
    r = np.linalg.norm(xy - kasa_circle(xy)[0], axis=1)
    c, sc = _slope(r0, r, through_origin=True)
    return {
        "local_axial_strain": 1 - b, "local_axial_sigma": sb,
        "local_radial_strain": 1 - c, "local_radial_sigma": sc,
    }  # fmt: skip
