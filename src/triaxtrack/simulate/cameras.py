"""The simulated cameras: a seeded ring around the cell, jittered and optionally pitched."""

from __future__ import annotations

import cv2
import numpy as np

from triaxtrack import footage
from triaxtrack.optics import Camera
from triaxtrack.simulate.config import SimulationConfig, camera_names

# placement jitter of the simulated cameras (uniform +- these)
JITTER_ANGLE_DEG = 1.5
JITTER_POSITION_MM = 3.0
JITTER_ROTATION_DEG = 0.7
JITTER_FOCAL_REL = 0.01
JITTER_PRINCIPAL_REL = 0.005
JITTER_K1, JITTER_K2, JITTER_P = 0.02, 0.01, 3e-4
TILT_STREAM = (0, 2)  # the per-camera seed stream of `camera_tilt_deg` (footage.camera_rng)


def look_at(center: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Rotation cell -> camera for a camera at ``center`` looking at ``target``, +z up in image."""
    fwd = target - center
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return np.vstack([right, down, fwd])


def make_cameras(cfg: SimulationConfig) -> list[Camera]:
    """A seeded ring of cameras around the cell, all looking at the axis.

    Each camera is placed with small seeded jitters (``JITTER_*``); with ``camera_tilt_deg`` it
    is then pitched about its own image x axis by an angle drawn uniformly in +- that many
    degrees (positive: the line of sight turns up, towards +z), from a generator of its own
    (``TILT_STREAM``), so the other parameters do not change with the tilt.
    """
    rng = np.random.default_rng(cfg.seed)
    cams = []
    w, h = cfg.width, cfg.height
    for i, name in enumerate(camera_names(cfg.cameras)):
        phi = 2 * np.pi * i / cfg.cameras + np.deg2rad(rng.uniform(-1, 1) * JITTER_ANGLE_DEG)
        rad = cfg.camera_radius_mm + rng.uniform(-1, 1) * JITTER_POSITION_MM
        c = np.array([rad * np.cos(phi), rad * np.sin(phi), cfg.camera_height_mm])
        c[2] += rng.uniform(-1, 1) * JITTER_POSITION_MM
        R0 = look_at(c, np.array([0.0, 0.0, cfg.camera_height_mm]))
        jitter = np.deg2rad(rng.uniform(-1, 1, 3) * JITTER_ROTATION_DEG)
        R = cv2.Rodrigues(jitter)[0] @ R0
        if cfg.camera_tilt_deg > 0:
            R = tilt_rotation(camera_pitch_deg(cfg, name)) @ R
        f = cfg.focal_factor * w * (1 + rng.uniform(-1, 1) * JITTER_FOCAL_REL)
        cx = (w - 1) / 2 + rng.uniform(-1, 1) * JITTER_PRINCIPAL_REL * w
        cy = (h - 1) / 2 + rng.uniform(-1, 1) * JITTER_PRINCIPAL_REL * h
        K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
        dist = np.array([
            cfg.k1 + rng.uniform(-1, 1) * JITTER_K1,
            cfg.k2 + rng.uniform(-1, 1) * JITTER_K2,
            rng.uniform(-1, 1) * JITTER_P,
            rng.uniform(-1, 1) * JITTER_P,
            0.0,
        ])  # fmt: skip
        cams.append(Camera(name, w, h, K, dist, R, -R @ c))
    return cams


def camera_pitch_deg(cfg: SimulationConfig, camera: str) -> float:
    """The seeded pitch of a camera, degrees, uniform in +- ``camera_tilt_deg``."""
    rng = footage.camera_rng(cfg.seed, camera, TILT_STREAM)
    return float(rng.uniform(-1, 1) * cfg.camera_tilt_deg)


def tilt_rotation(pitch_deg: float) -> np.ndarray:
    """(3, 3) rotation in the camera frame (x right, y down, z forward) turning the line of
    sight up by ``pitch_deg`` about the camera's x axis (applied as ``R' = P @ R``)."""
    return cv2.Rodrigues(np.r_[-np.deg2rad(pitch_deg), 0.0, 0.0])[0]
