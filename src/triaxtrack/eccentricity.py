"""Eccentricity of round marks seen through the cell: the centroid of a dot's image is not the
image of the dot's centre.

A printed dot is a disc on a curved surface (the membrane, a pedestal's side), seen in
perspective and through two refracting walls. The map from the disc to the image is not
affine across the dot, so the area centroid of its image, which the detector and the tracker
measure, lies off the image of its centre: the eccentricity error of circular targets in
photogrammetry. On the demo's membrane it is about 0.013 px, always in the same sense, and left
in it moved every triangulated dot about 5 micrometres towards the axis (0.03 % of the volume).

:func:`eccentricity_px` computes it from the dot's 3-D centre and printed radius: the outline
of the disc, drawn on the vertical cylinder through its centre coaxial with the cell (the
surface a membrane or pedestal dot lies on, its normal radial), is projected exactly
(:func:`triaxtrack.optics.project_water`, warm-started from the centre's ray); the area centroid
of the region the projected outline bounds (Green's theorem on ``OUTLINE_POINTS`` points, the
curve's derivative by FFT: exact for a smooth closed curve of few harmonics) minus the projected
centre is the eccentricity; in air (the cell wall's marks) the outline is projected without
refraction. It is taken off the observations where the points are solved: the cell wall's
bundle adjustment and the cameras posed through the wall (:mod:`triaxtrack.sfm`: on the demo
the fitted outer radius was 6.3 micrometres small, now 0.4), and the targets in the water
(:mod:`triaxtrack.triangulate`; over a chunk, computed every few frames and interpolated in time,
:func:`triaxtrack.timesteps.triangulate_frames`). Not modelled: the dot's own deformation (its size changes
with the membrane's strain, a few per cent of a quantity of 0.01 px) and the bulge's curvature
along the axis.

Units: millimetres in an axis frame of the cell (the cell axis is z); distorted pixels, OpenCV
convention.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from triaxtrack.kit_design import KitDesign
from triaxtrack.optics import Camera, CellOptics, project_air, project_water

OUTLINE_POINTS = 8  # points of the projected outline (the centroid's error: 6e-4 of it at 6 or more)


def disc_outline(centres_mm: np.ndarray, radius_mm: np.ndarray, n: int = OUTLINE_POINTS) -> np.ndarray:
    """(M, n, 3) points on the edge of discs of ``radius_mm`` (M,) centred at ``centres_mm``
    (M, 3), drawn on the vertical cylinder through each centre coaxial with z: arc length
    ``radius cos(phi)`` around the axis, height ``radius sin(phi)``."""
    c = np.asarray(centres_mm, float).reshape(-1, 3)
    rho = np.asarray(radius_mm, float).reshape(-1, 1)
    r = np.hypot(c[:, 0], c[:, 1])[:, None]
    phi = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)[None, :]
    theta = np.arctan2(c[:, 1], c[:, 0])[:, None] + rho * np.cos(phi) / r
    z = c[:, 2:3] + rho * np.sin(phi)
    return np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=-1)


def _centroid_offset(uv_centre: np.ndarray, uv_outline: np.ndarray) -> np.ndarray:
    """Area centroid of the regions bounded by closed smooth curves sampled at n equally spaced
    parameters (M, n, 2), minus the projected centres (M, 2): Green's theorem, the curve's
    derivative by FFT and the integrals by the trapezoidal rule, both exact to rounding for a
    smooth periodic curve of few harmonics (the error falls exponentially with n)."""
    xy = uv_outline - uv_centre[:, None, :]
    n = xy.shape[1]
    k = np.fft.fftfreq(n, 1.0 / n)
    if n % 2 == 0:
        k[n // 2] = 0.0  # the Nyquist term has no derivative
    d = np.fft.ifft(1j * k[None, :, None] * np.fft.fft(xy, axis=1), axis=1).real
    x, y, dx, dy = xy[..., 0], xy[..., 1], d[..., 0], d[..., 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        a2 = 2.0 * (x * dy).sum(axis=1)
        return np.stack([(x * x * dy).sum(axis=1) / a2, -(y * y * dx).sum(axis=1) / a2], axis=1)


def eccentricity_px(
    camera: Camera, centres_mm: np.ndarray, radius_mm: np.ndarray, cell: CellOptics | None
) -> np.ndarray:
    """(M, 2) eccentricity (pixels) of the images in ``camera`` of round marks of printed radius
    ``radius_mm`` (M,) centred at ``centres_mm`` (M, 3): the area centroid of the image minus
    the image of the centre (see the module). The marks are in the water, seen through ``cell``,
    or, with ``cell`` None, in air (the cell wall's). NaN where the mark does not project."""
    c = np.asarray(centres_mm, float).reshape(-1, 3)
    n = OUTLINE_POINTS
    outline = disc_outline(c, radius_mm, n).reshape(-1, 3)
    if cell is None:
        return _centroid_offset(project_air(camera, c), project_air(camera, outline).reshape(len(c), n, 2))
    uv_c, _, sol = project_water(camera, c, cell)
    uv_o = project_water(camera, outline, cell, xy0=np.repeat(sol.xy, n, axis=0),
                         pinv0=np.repeat(sol.pinv, n, axis=0))[0].reshape(len(c), n, 2)  # fmt: skip
    return _centroid_offset(uv_c, uv_o)


def observation_eccentricity(
    cameras: dict[str, Camera],
    cam_of: np.ndarray,
    centres_mm: np.ndarray,
    radius_mm: np.ndarray,
    cell: CellOptics | None,
) -> np.ndarray:
    """(N, 2) eccentricity (pixels) of N observations: camera names ``cam_of``, the 3-D centres
    of their marks ``centres_mm`` (N, 3) and printed radii ``radius_mm`` (N,; NaN: not a round
    mark, no correction), in the water seen through ``cell`` or in air (``cell`` None). 0 where
    the radius or the centre is not finite, the camera is not in ``cameras`` or the outline does
    not project."""
    ecc = np.zeros((len(cam_of), 2))
    rad = np.asarray(radius_mm, float)
    todo = np.isfinite(rad) & (rad > 0) & np.isfinite(centres_mm).all(axis=1) & np.isin(cam_of, list(cameras))
    for name in np.unique(cam_of[todo]):
        sel = todo & (cam_of == name)
        ecc[sel] = eccentricity_px(cameras[name], centres_mm[sel], rad[sel], cell)
    return np.where(np.isfinite(ecc), ecc, 0.0)


def mark_radii(design: KitDesign, table: pd.DataFrame) -> pd.Series:
    """Printed radius (mm) of the round mark whose centroid is measured, by target ID: a dot's
    own radius, a coded target's centre dot (the kit's ``coded_target.centre_radius``).
    ``design``: the kit (:func:`triaxtrack.kit.load_kit_design`); ``table``: its
    :func:`triaxtrack.kit.target_table`."""
    centre = float(design.coded_target.centre_radius)
    radius = np.where(table["kind"] == "coded", centre, table["diameter_mm"].to_numpy(float) / 2)
    return pd.Series(radius, index=table["id"].to_numpy(), name="mark_radius_mm")
