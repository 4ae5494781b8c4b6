"""Local Green-Lagrange membrane strains per grid cell (dimensionless, tension positive)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from triaxtrack.volume.grid import MembraneGrid


def strain_field(grid: MembraneGrid, grid0: MembraneGrid) -> pd.DataFrame:
    """Green-Lagrange membrane strain per grid cell, tension positive.

    Each cell (between grid rows i, i + 1 and columns j, j + 1, periodic) gets the tangents
    ``x_theta, x_z`` (means of its two edges in each direction) in this frame and in ``grid0``;
    ``F = A M0^-1`` maps the undeformed cell's orthonormal tangent basis (e_theta along the
    undeformed x_theta, e_z completing it in the tangent plane) to the current tangents, and
    ``E = (F^T F - I) / 2``. Columns: ``row, col`` (1-based kit numbers of the cell's upper row
    and of its first column in theta), ``theta_rad, z_mm`` the cell centre in design coordinates,
    ``e_zz, e_tt, e_tz``.
    """

    def tangents(g: MembraneGrid) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(g.xyz, float)
        x1 = np.roll(x, -1, axis=1)
        a_t = 0.5 * ((x1 - x)[:-1] + (x1 - x)[1:])
        a_z = 0.5 * ((x[1:] - x[:-1]) + (x1[1:] - x1[:-1]))
        return a_t, a_z

    if grid.xyz.shape != grid0.xyz.shape:
        raise ValueError("the grid and the reference grid differ in shape")
    a_t, a_z = tangents(grid)
    b_t, b_z = tangents(grid0)
    e1 = b_t / np.linalg.norm(b_t, axis=-1, keepdims=True)
    e2 = b_z - np.sum(b_z * e1, axis=-1, keepdims=True) * e1
    e2 /= np.linalg.norm(e2, axis=-1, keepdims=True)
    basis = np.stack([e1, e2], axis=-1)  # (.., 3, 2)
    m0 = np.swapaxes(basis, -1, -2) @ np.stack([b_t, b_z], axis=-1)  # (.., 2, 2)
    f = np.stack([a_t, a_z], axis=-1) @ np.linalg.inv(m0)  # (.., 3, 2)
    e = 0.5 * (np.swapaxes(f, -1, -2) @ f - np.eye(2))
    n_r, n_c = grid.measured.shape
    theta = np.asarray(grid.theta, float)
    dth = np.diff(np.append(theta, theta[0] + 2 * np.pi))
    z = np.asarray(grid.z, float)
    rows = np.asarray(grid.rows)
    row = np.minimum(rows[:-1], rows[1:])
    return pd.DataFrame({
        "row": np.repeat(row, n_c).astype(np.int64),
        "col": np.tile(np.asarray(grid.cols), n_r - 1).astype(np.int64),
        "theta_rad": np.tile(np.mod(theta + dth / 2, 2 * np.pi), n_r - 1),
        "z_mm": np.repeat(0.5 * (z[:-1] + z[1:]), n_c),
        "e_zz": e[..., 1, 1].ravel(),
        "e_tt": e[..., 0, 0].ravel(),
        "e_tz": e[..., 0, 1].ravel(),
    }).sort_values(["row", "col"], kind="stable").reset_index(drop=True)  # fmt: skip
