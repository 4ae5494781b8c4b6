"""How much each observation moved its 3-D point, and the uncertainty of anything computed from
the points when one camera's errors are shared by all its observations.

A point's standard error from its rays (``sigma_mm``) is honest for the point alone, but the
errors of one camera's observations in one frame are not independent: a pose that is slightly
off, the frame's common jitter or its codec's departure move every mark that camera sees
together. A sum over thousands of points (a volume, a mean strain) then averages the
independent part away and keeps the shared part, and a propagation that takes the points as
independent is several times too small (on clean simulated tests, 1.5-3.4 mm^3 against a
frame-to-frame volume error of 5-9 mm^3).

The remedy is the cluster-robust ("sandwich") variance of regression, with the cameras as the
clusters:

* **Influence of an observation** (:func:`observation_influence`). A point ``x`` solves
  ``min sum_i |J_i dx + r_i|^2`` over its rays (``r_i`` the reprojection minus the observation,
  px; ``J_i`` the projection's Jacobian, px/mm; ``H = sum J_i^T J_i``). An error ``e_i`` of
  observation ``i`` moves the point by ``H^-1 J_i^T e_i``. The residual estimates ``-e_i`` but is
  shrunk by the observation's own pull on the point, its leverage ``h_i = J_i H^-1 J_i^T``
  (2 x 2): ``-(I - h_i)^-1/2 r_i`` has the error's variance (the CR2 / HC2 correction). So the
  influence is ``psi_i = -H^-1 J_i^T (I - h_i)^-1/2 r_i`` (mm, cell frame).
* **Cluster sum** (:func:`cluster_sigma`). For a statistic ``S`` of the points with gradient
  ``g_p`` (per point, ``dS/dx_p``), camera ``c`` moves ``S`` by ``s_c = sum_{i in c} g_p(i) . psi_i``;
  with cameras independent of each other (errors within one camera correlated in any way),
  ``var S = sum_c s_c^2``. With independent observations it is the usual propagation; with a
  camera's errors shared, it grows by exactly their correlation.

What it cannot see: an error common to every camera (the cell's refraction model, a bias of
every centroid alike), since the rays then agree with each other. Where such an error's size is
known from elsewhere (the codec correction's own uncertainty, :mod:`triaxtrack.codec_lag`), it
is carried by **shared shifts** (:func:`observation_shift`, :func:`shared_sigma`): each point's
displacement by that error at 1 sigma, in every camera at once, summed over its observations;
the statistic moves by the sum over every point, in full.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

MIN_RESIDUAL_SHARE = 0.01  # (I - h) eigenvalues floored here: a ray with nearly all the say, x10 at most
INFLUENCE_COLUMNS = ("ix_mm", "iy_mm", "iz_mm")
# a point's shift (mm) by the codec correction's uncertainty along the images' u, then v axis
CODEC_SHIFT_COLUMNS = (
    "codec_ux_mm", "codec_uy_mm", "codec_uz_mm", "codec_vx_mm", "codec_vy_mm", "codec_vz_mm",
)  # fmt: skip


def observation_influence(
    jac: np.ndarray, cov: np.ndarray, group: np.ndarray, resid: np.ndarray
) -> np.ndarray:
    """(N, 3) influence (mm) of each observation on its point (see the module): ``jac`` (N, 2, 3)
    px/mm, ``cov`` (M, 3, 3) each point's ``(J^T J)^-1`` (mm^2/px^2), ``group`` (N,) the point of
    each observation, ``resid`` (N, 2) reprojection minus observation (px). NaN where the point
    or the residual is not finite."""
    h_inv = np.asarray(cov, float)[np.asarray(group)]
    jac, resid = np.asarray(jac, float), np.asarray(resid, float)
    ok = np.isfinite(h_inv).all(axis=(1, 2)) & np.isfinite(jac).all(axis=(1, 2))
    ok &= np.isfinite(resid).all(axis=1)
    out = np.full((len(jac), 3), np.nan)
    if not ok.any():
        return out
    j, hi, r = jac[ok], h_inv[ok], resid[ok]
    lev = np.einsum("nki,nij,nlj->nkl", j, hi, j)
    w, v = np.linalg.eigh(np.eye(2) - 0.5 * (lev + np.swapaxes(lev, 1, 2)))
    scale = np.einsum("nij,nj,nkj->nik", v, np.clip(w, MIN_RESIDUAL_SHARE, None) ** -0.5, v)
    err = np.einsum("nij,nj->ni", scale, r)
    out[ok] = -np.einsum("nij,nkj,nk->ni", hi, j, err)
    return out


def cluster_sigma(influence: pd.DataFrame, gradient: pd.DataFrame) -> tuple[float, int]:
    """Standard uncertainty of a statistic of one frame's points, cameras as clusters (see the
    module), and the number of cameras that contribute. ``influence``: rows ``camera, id,
    ix_mm, iy_mm, iz_mm`` (one per observation used); ``gradient``: rows ``id, gx, gy, gz`` (the
    statistic's derivative by each point's x, y, z; points absent do not enter it). NaN and 0
    when no observation meets the gradient."""
    inf, grad = _meeting(influence, gradient)
    ds = np.einsum("ni,ni->n", inf[list(INFLUENCE_COLUMNS)].to_numpy(float), grad)
    ok = np.isfinite(ds)
    if not ok.any():
        return float("nan"), 0
    per_camera = pd.Series(ds[ok]).groupby(inf["camera"].to_numpy()[ok]).sum()
    return float(np.sqrt(np.sum(per_camera.to_numpy() ** 2))), len(per_camera)


def observation_shift(jac: np.ndarray, cov: np.ndarray, group: np.ndarray, error: np.ndarray) -> np.ndarray:
    """(N, 3) shift (mm) of each observation's point by an ``error`` (N, 2, px) of that
    observation, ``H^-1 J^T e`` (arguments as :func:`observation_influence`); NaN where the point
    or the Jacobian is not finite."""
    h_inv = np.asarray(cov, float)[np.asarray(group)]
    return np.einsum("nij,nkj,nk->ni", h_inv, np.asarray(jac, float), np.asarray(error, float))


def shared_sigma(shifts: pd.DataFrame, gradient: pd.DataFrame) -> float:
    """Standard uncertainty of a statistic of one frame's points from errors every camera
    shares: ``shifts`` rows ``id`` and :data:`CODEC_SHIFT_COLUMNS` (each point's displacement by
    the error along the images' u, then v axis, at 1 sigma; the two axes independent),
    ``gradient`` as :func:`cluster_sigma`'s. Each axis moves the statistic by ``sum_p g_p . s_p``
    over every point, in full; 0 when no point meets the gradient."""
    s, grad = _meeting(shifts, gradient)
    if s.empty:
        return 0.0
    cols = list(CODEC_SHIFT_COLUMNS)
    per_axis = [np.nansum(np.einsum("ni,ni->n", s[cols[a : a + 3]].to_numpy(float), grad)) for a in (0, 3)]
    return float(np.hypot(*per_axis))


def _meeting(rows: pd.DataFrame, gradient: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray]:
    """The ``rows`` (with an ``id``) whose point the ``gradient`` has, and that gradient per row
    (n, 3)."""
    g = gradient.set_index("id")[["gx", "gy", "gz"]]
    mine = rows[rows["id"].isin(g.index)]
    return mine, g.loc[mine["id"]].to_numpy(float)
