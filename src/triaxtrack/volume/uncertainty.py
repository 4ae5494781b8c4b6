"""Standard uncertainty (1-sigma, mm^3) of one frame's soil volume.

Four independent parts, added in quadrature:

* ``measured``: the measured dots' and the top cap's position errors, the larger of two
  estimates:

  - ``cameras_mm3``, cameras as clusters (:mod:`triaxtrack.influence`): each used observation's
    influence on its point (from the triangulation's residuals) times the volume's derivative
    by that point -- ``A n`` for a measured membrane dot (its area element ``A``, mm^2, and
    outward normal ``n``, :func:`dot_areas`), ``V / h / n_cap`` along the cap's axis for each of
    the ``n_cap`` top-cap coded targets of its rigid fit -- summed per camera, the sums added in
    quadrature. It carries what one camera's observations share (its pose, a frame's common
    jitter, its codec), which the independent model below misses: on clean simulated tests the
    volume error from frame to frame is 2-4 times that model's;
  - the independent model: a dot's error along the normal moves the surface by that much over
    its area, dots independent, ``sum (A sigma_n)^2``, ``sigma_n = sigma_mm / sqrt(3)`` from
    points.parquet's ``sigma_mm`` (the 3-D standard error, isotropic assumed; without it, the
    noise from the grid itself, :func:`point_noise_mm`); plus the top face's height, from the
    rigid fit's residual (``rms / sqrt(3 n - 6)``), times dV/dh taken as the mean
    cross-section V / h (``cap_mm3``). It is what is left with no influences (observations
    not given) and a floor under the cluster estimate, which rests on a dozen cameras.
* ``codec``: the codec correction's own uncertainty (:mod:`triaxtrack.codec_lag`: a rigid
  body's P-frame offset is pooled over every camera, so its error is in every camera at once,
  and where it is too uncertain to be taken off, the offset measured is left in the P frames),
  which no residual shows: the points' shifts by it (points.parquet's ``codec_*_mm``) times the
  gradient above, summed over every point (:func:`triaxtrack.influence.shared_sigma`). On a
  clean 1080p test with two keyframes, the top cap's offset (-0.014 px in every camera) is
  left in, and reads the cap 2.8 micrometres low in every P frame.
* ``fill``: the error of the filled dots, by a leave-out check on this frame's measured dots.
  Every gap (connected set of missing dots) is moved, with all the others, to other places of
  the grid -- turned by multiples of 1/8 turn, and mirrored top to bottom (an end band onto the
  other end) -- where its dots were measured; those dots are hidden, the grid filled again by
  the same rule, and the fill's volume error there, ``sum A (x_fill - x_measured) . n``, is one
  sample of that gap's error. A gap's variance is the mean square of its samples; gaps are
  independent. A gap with no place to go borrows the worst error per area seen elsewhere; with
  no sample at all the fill's part is unknown (NaN).

Not included: other errors every camera shares (the cell's refraction model, a bias of every
centroid alike: :mod:`triaxtrack.influence`; the membrane's codec departure, fitted per
camera), the method's own discretisation error (2.8e-7 of the volume on a loaded simulator
frame) and, in a shear band, the membrane thickness model's error (about 1e-5 of the volume).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from triaxtrack.influence import cluster_sigma, shared_sigma
from triaxtrack.volume.cap import TopCap
from triaxtrack.volume.grid import FaceEnds, MembraneGrid, fill_grid, gap_labels

TRIAL_TURNS = 8  # gaps are moved by multiples of 1/8 turn (and mirrored): up to 15 leave-out fills
MAD_TO_SIGMA = 1.4826  # median absolute deviation of a normal distribution -> its sigma
D4_VARIANCE = 70.0  # sum of squared weights of the 4th difference (1, -4, 6, -4, 1)


@dataclass(frozen=True)
class VolumeUncertainty:
    """1-sigma standard uncertainty of a soil volume and its parts, mm^3 (see the module)."""

    sigma_mm3: float
    measured_mm3: float
    fill_mm3: float
    cap_mm3: float
    fill_samples: int
    cameras_mm3: float = float("nan")  # the cluster estimate (NaN: no influences given)
    cameras: int = 0  # the cameras that contribute to it
    codec_mm3: float = 0.0  # the codec correction's part (0: no shifts given)
    height_mm: float = float("nan")  # the height's (mm, :func:`height_sigma_mm`; NaN: not computed)


def dot_areas(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area element (R, C) mm^2 of each dot of an (R, C, 3) grid (R >= 2; central differences,
    periodic in the columns) and the outward unit normals (R, C, 3)."""
    d_th = 0.5 * (np.roll(xyz, -1, axis=1) - np.roll(xyz, 1, axis=1))
    d_z = np.gradient(xyz, axis=0)
    n = np.cross(d_th, d_z)
    area = np.linalg.norm(n, axis=-1)
    return area, n / area[..., None]


def point_noise_mm(grid: MembraneGrid, normal: np.ndarray) -> float:
    """Noise (mm, 1-sigma, along the normal) of the measured dots, from the 4th differences
    along the rows of runs of five measured dots (a smooth surface's are ~1e-4 of them); 0 when
    there is no such run."""
    x, m = np.asarray(grid.xyz, float), np.asarray(grid.measured)
    shifts = [np.roll(x, -s, axis=1) for s in (-2, -1, 0, 1, 2)]
    d4 = shifts[0] - 4 * shifts[1] + 6 * shifts[2] - 4 * shifts[3] + shifts[4]
    ok = np.all([np.roll(m, -s, axis=1) for s in (-2, -1, 0, 1, 2)], axis=0)
    if not ok.any():
        return 0.0
    dn = np.einsum("rck,rck->rc", d4, normal)[ok]
    return float(MAD_TO_SIGMA * np.median(np.abs(dn)) / np.sqrt(D4_VARIANCE))


def fill_sigma_mm3(grid: MembraneGrid, ends: FaceEnds | None) -> tuple[float, int]:
    """The fill's part (mm^3, 1-sigma; NaN when no leave-out sample exists) and the number of
    samples (see the module docstring)."""
    miss = ~np.asarray(grid.measured)
    lab, n = gap_labels(miss)
    if n == 0:
        return 0.0, 0
    x = np.asarray(grid.xyz, float)
    area, normal = dot_areas(x)
    n_c = miss.shape[1]
    step = max(n_c // TRIAL_TURNS, 1)
    trials = [(False, k * step) for k in range(1, TRIAL_TURNS)]
    trials += [(True, k * step) for k in range(TRIAL_TURNS)]
    samples: list[list[float]] = [[] for _ in range(n + 1)]
    per_area: list[float] = []
    gap_area = np.bincount(lab.ravel(), weights=area.ravel(), minlength=n + 1)
    for mirror, shift in trials:
        moved = np.roll(lab[::-1] if mirror else lab, shift, axis=1)  # gap label moved onto each dot
        blocked = np.unique(moved[(moved > 0) & miss])
        valid = np.setdiff1d(np.arange(1, n + 1), blocked)
        if valid.size == 0:
            continue
        hidden = (moved > 0) & ~miss
        try:
            x_t = fill_grid(np.where(hidden[..., None], np.nan, x), ~miss & ~hidden, grid.theta, grid.z, ends)
        except ValueError:
            continue
        dv = np.einsum("rck,rck->rc", x_t - x, normal) * area
        err = np.bincount(moved[hidden], weights=dv[hidden], minlength=n + 1)
        moved_area = np.bincount(moved[hidden], weights=area[hidden], minlength=n + 1)
        for g in valid:
            samples[g].append(float(err[g]))
            per_area.append(abs(err[g]) / moved_area[g])
    n_samples = sum(len(s) for s in samples)
    if not per_area:
        return float("nan"), 0
    worst = max(per_area)
    var = sum(np.mean(np.square(s)) if s else (worst * gap_area[g]) ** 2 for g, s in enumerate(samples) if g)
    return float(np.sqrt(var)), n_samples


def volume_gradient(
    grid: MembraneGrid, ids: np.ndarray, cap: TopCap, cap_ids: np.ndarray, volume_mm3: float
) -> pd.DataFrame:
    """The volume's derivative (mm^2) by each point it is measured from, rows ``id, gx, gy, gz``:
    ``A n`` for each measured membrane dot (``ids`` (R, C) the grid's dot IDs,
    :func:`~triaxtrack.volume.grid.grid_ids`) and, when the cap comes from its coded targets,
    ``V / h / n_cap`` along its axis for each of ``cap_ids`` (the top cap's targets in this
    frame)."""
    area, normal = dot_areas(np.asarray(grid.xyz, float))
    m = np.asarray(grid.measured)
    dots = (area[..., None] * normal)[m]
    g = pd.DataFrame({"id": ids[m], "gx": dots[:, 0], "gy": dots[:, 1], "gz": dots[:, 2]})
    top = height_gradient(cap, cap_ids)  # dV/dh = V / h, the mean cross-section
    top[["gx", "gy", "gz"]] *= abs(volume_mm3 / cap.height_mm)
    return pd.concat([g, top], ignore_index=True) if len(top) else g


def height_gradient(cap: TopCap, cap_ids: np.ndarray) -> pd.DataFrame:
    """The height's derivative by each of the top cap's coded targets ``cap_ids`` (rows ``id, gx,
    gy, gz``): the face's axis over their number (the face is their rigid fit); none when the cap
    does not come from its coded targets."""
    if cap.source != "coded targets" or not len(cap_ids):
        return pd.DataFrame({"id": np.zeros(0, np.int64), "gx": [], "gy": [], "gz": []})
    axis = np.asarray(cap.face_normal, float) / cap.n_targets
    return pd.DataFrame({"id": np.asarray(cap_ids, np.int64), "gx": axis[0], "gy": axis[1], "gz": axis[2]})


def height_sigma_mm(
    cap: TopCap,
    influence: pd.DataFrame | None = None,
    gradient: pd.DataFrame | None = None,
    shifts: pd.DataFrame | None = None,
) -> float:
    """1-sigma standard uncertainty (mm) of the specimen's height (its top face above the bottom
    face, which the pedestal frame fixes), as the volume's (:func:`volume_uncertainty`): the larger
    of the face's own standard error (``TopCap.face_sigma_mm``: the rigid fit's residual over
    ``sqrt(3 n - 6)``, or a face carried up from the membrane's) and the cameras' cluster estimate
    with ``influence`` and the height's ``gradient`` (:func:`height_gradient`), and the codec's part
    with the points' ``shifts``, in quadrature."""
    part, _, _, codec = _measured_parts(cap.face_sigma_mm, influence, gradient, shifts)
    return float(np.hypot(part, codec))


def _measured_parts(
    independent: float,
    influence: pd.DataFrame | None,
    gradient: pd.DataFrame | None,
    shifts: pd.DataFrame | None,
) -> tuple[float, float, int, float]:
    """A statistic's measured part -- the larger of its ``independent`` model and the cameras'
    cluster estimate (with ``influence`` and its ``gradient``) -- the cluster estimate (NaN
    without), the cameras in it, and the codec's part (with the points' ``shifts``; else 0)."""
    cameras, n_cameras = float("nan"), 0
    if influence is not None and gradient is not None and len(influence) and len(gradient):
        cameras, n_cameras = cluster_sigma(influence, gradient)
    part = max(independent, cameras) if np.isfinite(cameras) else independent
    codec = shared_sigma(shifts, gradient) if shifts is not None and gradient is not None else 0.0
    return part, cameras, n_cameras, codec


def volume_uncertainty(
    grid: MembraneGrid,
    ends: FaceEnds | None,
    cap: TopCap,
    volume_mm3: float,
    influence: pd.DataFrame | None = None,
    gradient: pd.DataFrame | None = None,
    shifts: pd.DataFrame | None = None,
) -> VolumeUncertainty:
    """1-sigma standard uncertainty of one frame's soil volume ``volume_mm3`` (mm^3) measured
    from ``grid`` (filled with ``ends``) and ``cap``; with this frame's observations'
    ``influence`` (rows ``camera, id, ix_mm, iy_mm, iz_mm``) and the volume's ``gradient``
    (:func:`volume_gradient`), the measured part is the larger of the cameras' cluster estimate
    and the independent model; with the points' codec ``shifts`` (rows ``id`` and
    :data:`~triaxtrack.influence.CODEC_SHIFT_COLUMNS`) and the ``gradient``, the codec's part is
    added; see the module docstring."""
    area, normal = dot_areas(np.asarray(grid.xyz, float))
    m = np.asarray(grid.measured)
    noise = point_noise_mm(grid, normal)
    sig = np.full(m.shape, noise)
    if grid.sigma_mm is not None:
        given = np.isfinite(grid.sigma_mm)
        sig[given] = np.asarray(grid.sigma_mm)[given] / np.sqrt(3)
    measured = float(np.sqrt(np.sum((area[m] * sig[m]) ** 2)))
    fill, n_samples = fill_sigma_mm3(grid, ends)
    cap_part = abs(volume_mm3 / cap.height_mm) * cap.face_sigma_mm
    carried = cap.source != "coded targets"  # a face carried up from the membrane: no camera's sum holds it
    independent = float(np.hypot(measured, 0.0 if carried else cap_part))
    part, cameras, n_cameras, codec = _measured_parts(independent, influence, gradient, shifts)
    total = float(np.sqrt(part**2 + fill**2 + codec**2 + (cap_part**2 if carried else 0.0)))
    return VolumeUncertainty(total, measured, fill, float(cap_part), n_samples, cameras, n_cameras, codec)
