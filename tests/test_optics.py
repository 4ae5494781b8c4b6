"""Refraction and projection against independent physics."""

from __future__ import annotations

import cv2
import numpy as np
from scipy.optimize import least_squares

from triaxtrack.optics import Camera, CellOptics, project_air, project_water, trace_into_water
from triaxtrack.simulate import look_at

CELL = CellOptics(outer_radius=77.0, inner_radius=65.0, n_acrylic=1.491, n_water=1.333, z_min=-50, z_max=200)


def ring_camera(phi=0.3, z=72.0) -> Camera:
    c = np.array([340 * np.cos(phi), 340 * np.sin(phi), z])
    R = look_at(c, np.array([0, 0, 70.0]))
    K = np.array([[794.0, 0, 641.2], [0, 794.0, 357.9], [0, 0, 1]])
    return Camera("c", 1280, 720, K, np.array([-0.29, 0.085, 2e-4, -1e-4, 0.0]), R, -R @ c)


def membrane_points(n=300, seed=0, phi=0.3):
    rng = np.random.default_rng(seed)
    th = phi + rng.uniform(-1.0, 1.0, n)
    return np.c_[35.85 * np.cos(th), 35.85 * np.sin(th), rng.uniform(2, 140, n)]


def test_air_projection_is_opencv():
    cam = ring_camera()
    rng = np.random.default_rng(1)
    th = 0.3 + rng.uniform(-0.8, 0.8, 100)
    pts = np.c_[77 * np.cos(th), 77 * np.sin(th), rng.uniform(-40, 190, 100)]
    uv_cv, _ = cv2.projectPoints(pts, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)
    assert np.abs(project_air(cam, pts) - uv_cv.reshape(-1, 2)).max() < 1e-9


def test_both_refractions_obey_snell():
    cam, pts = ring_camera(), membrane_points()
    uv, d2, sol = project_water(cam, pts, CELL)
    ok = np.isfinite(uv).all(axis=1)
    assert ok.mean() > 0.95
    path = trace_into_water(cam, sol.xy[ok], CELL)

    def sin_and_plane(d_in, d_out, p):
        n = np.c_[p[:, 0], p[:, 1], np.zeros(len(p))]
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        s_in = np.linalg.norm(np.cross(d_in, n), axis=1)
        s_out = np.linalg.norm(np.cross(d_out, n), axis=1)
        coplanar = np.abs(np.einsum("ij,ij->i", np.cross(d_in, n), d_out))
        return s_in, s_out, coplanar

    s0, s1, cop1 = sin_and_plane(path.dir_air, path.dir_acrylic, path.outer_hit)
    assert np.abs(1.0 * s0 - CELL.n_acrylic * s1).max() < 1e-9
    s1b, s2, cop2 = sin_and_plane(path.dir_acrylic, path.dir_water, path.inner_hit)
    assert np.abs(CELL.n_acrylic * s1b - CELL.n_water * s2).max() < 1e-9
    assert max(cop1.max(), cop2.max()) < 1e-9
    # and the water ray passes through the point
    v = pts[ok] - path.inner_hit
    off = v - np.einsum("ij,ij->i", v, path.dir_water)[:, None] * path.dir_water
    assert np.linalg.norm(off, axis=1).max() < 1e-6  # the solver's tolerance


def test_water_projection_matches_brute_force_solver():
    """An independent solve (scipy least squares from a far start) agrees to 1e-5 px."""
    cam, pts = ring_camera(phi=-1.1), membrane_points(20, seed=3, phi=-1.1)
    uv, _, sol = project_water(cam, pts, CELL)
    for p, q, x in zip(pts, uv, sol.xy, strict=True):
        if not np.isfinite(q).all():
            continue

        def resid(xyq, p=p):
            path = trace_into_water(cam, xyq.reshape(1, 2), CELL)
            v = p - path.inner_hit[0]
            return v - v @ path.dir_water[0] * path.dir_water[0]

        sol = least_squares(resid, x + [0.02, -0.015], xtol=1e-15, ftol=1e-15, gtol=1e-15)
        uv_bf, _ = cv2.projectPoints(
            np.r_[sol.x, 1.0].reshape(1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist
        )
        assert np.abs(uv_bf.reshape(2) - q).max() < 1e-5


def test_refraction_matters_by_pixels():
    cam, pts = ring_camera(), membrane_points()
    uv, _, _ = project_water(cam, pts, CELL)
    ok = np.isfinite(uv).all(axis=1)
    straight = project_air(cam, pts[ok])
    assert np.median(np.linalg.norm(straight - uv[ok], axis=1)) > 5.0


def test_no_refraction_reduces_to_pinhole():
    flat = CellOptics(77.0, 65.0, 1.0, 1.0)
    cam, pts = ring_camera(), membrane_points(50)
    uv, _, _ = project_water(cam, pts, flat)
    ok = np.isfinite(uv).all(axis=1)
    assert np.abs(uv[ok] - project_air(cam, pts[ok])).max() < 1e-6


def test_warm_start_with_cached_jacobian_gives_the_same_answer():
    cam, pts = ring_camera(), membrane_points(200, seed=5)
    _, _, first = project_water(cam, pts, CELL)
    moved = pts + [0.05, -0.03, -0.07]  # one frame of deformation
    cold, _, _ = project_water(cam, moved, CELL)
    warm, _, _ = project_water(cam, moved, CELL, first.xy, first.pinv)
    ok = np.isfinite(cold).all(axis=1)
    assert ok.sum() > 150 and np.isfinite(warm[ok]).all()
    assert np.abs(cold[ok] - warm[ok]).max() < 1e-5
