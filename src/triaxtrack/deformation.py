"""Kinematics of a deforming triaxial specimen (the simulator's ground truth).

Material coordinates: ``(theta, Z)`` on the undeformed membrane, ``theta`` in radians from +x,
``Z`` in mm from the bottom pedestal face (0) to the top (``height``). The loading progress
``p`` runs from 0 (first frame) to 1 (last frame); the axial strain grows linearly with ``p``
(a strain-controlled test).

The soil boundary is the membrane's *inner* surface::

    x(theta, Z) = c(Z) + rho(theta, Z) (cos theta, sin theta),   z(Z) = (H0 - dH) g(Z / H0)

* ``rho = R0 + b(p) phi(zeta) (1 + a cos(theta - theta_b))``: a barrel bulge ``phi`` (zero at
  both ends, peak at ``bulge_peak``, by default in the lower part as the paper observed), with
  an azimuthal asymmetry ``a``;
* ``g(zeta) = zeta - k(p) zeta (1 - zeta)``: the lower part compresses more;
* ``c(Z)``: the axis offset of an optional shear band (a smooth step of width
  ``shear_width`` at ``shear_z``), zero at the bottom and equal to the top cap's lateral
  displacement at the top.

The printed (outer) surface is the inner surface offset along its outward normal by the
membrane thickness ``t = t0 / (lambda_theta lambda_Z)`` (incompressible rubber thins as it
stretches). The soil volume is inside the inner surface between the pedestal faces and is
integrated exactly (Gauss-Legendre in Z, trapezoidal in theta: spectrally accurate for these
smooth periodic integrands).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

FD_H = 1e-6  # finite-difference step (rad, mm) for surface tangents


@lru_cache(maxsize=64)
def _envelope_peak(peak: float, width: float) -> float:
    """Maximum of the bulge envelope, so that the bulge profile peaks at exactly 1."""
    zz = np.linspace(0, 1, 20001)
    return float(np.max(np.sin(np.pi * zz) * np.exp(-(((zz - peak) / width) ** 2))))


@dataclass(frozen=True)
class Deformation:
    """Loading history of a simulated test. Lengths in mm, angles in radians."""

    radius: float = 35.55  # soil radius R0 (inner membrane surface), undeformed
    height: float = 142.2  # H0
    membrane_thickness: float = 0.3  # t0
    axial_strain: float = 0.05  # final axial strain (compression positive)
    bulge_mm: float = 2.0  # final peak radial bulge of the soil surface
    bulge_peak: float = 0.35  # zeta of the bulge peak (0 bottom, 1 top)
    bulge_width: float = 0.35  # Gaussian width of the bulge envelope, in zeta
    bulge_asymmetry: float = 0.15  # a: azimuthal variation of the bulge
    bulge_azimuth: float = 0.6  # theta_b
    axial_nonuniformity: float = 0.3  # final k: the lower part compresses more
    shear_mm: float = 0.0  # final lateral offset of the top cap (shear band); 0 = none
    shear_z: float = 0.55  # zeta of the shear band
    shear_width: float = 0.06  # width of the shear band, in zeta
    shear_azimuth: float = 0.0  # direction of the shear offset

    # ----------------------------------------------------------------- profiles
    def _phi(self, zeta: np.ndarray) -> np.ndarray:
        env = np.sin(np.pi * zeta) * np.exp(-(((zeta - self.bulge_peak) / self.bulge_width) ** 2))
        return env / _envelope_peak(self.bulge_peak, self.bulge_width)

    def _step(self, zeta: np.ndarray) -> np.ndarray:
        def s(u):
            return 0.5 * (1 + np.tanh((u - self.shear_z) / self.shear_width))

        return (s(zeta) - s(0.0)) / (s(1.0) - s(0.0))

    def top_displacement(self, p: float) -> np.ndarray:
        """(3,) displacement of the top cap (and the top pedestal) at progress p, mm."""
        off = self.shear_mm * p
        return np.array(
            [
                off * np.cos(self.shear_azimuth),
                off * np.sin(self.shear_azimuth),
                -self.axial_strain * p * self.height,
            ]
        )

    def current_height(self, p: float) -> float:
        return self.height * (1 - self.axial_strain * p)

    # ----------------------------------------------------------------- surfaces
    def inner_surface(self, theta: np.ndarray, Z: np.ndarray, p: float) -> np.ndarray:
        """(N, 3) points of the soil surface at material (theta, Z), progress p."""
        theta = np.asarray(theta, float)
        zeta = np.asarray(Z, float) / self.height
        rho = self.radius + self.bulge_mm * p * self._phi(zeta) * (
            1 + self.bulge_asymmetry * np.cos(theta - self.bulge_azimuth)
        )
        k = self.axial_nonuniformity * p
        z = self.current_height(p) * (zeta - k * zeta * (1 - zeta))
        off = self.shear_mm * p * self._step(zeta)
        x = off * np.cos(self.shear_azimuth) + rho * np.cos(theta)
        y = off * np.sin(self.shear_azimuth) + rho * np.sin(theta)
        return np.stack([x, y, z], axis=-1)

    def _frame(self, theta: np.ndarray, Z: np.ndarray, p: float):
        xt = (self.inner_surface(theta + FD_H, Z, p) - self.inner_surface(theta - FD_H, Z, p)) / (2 * FD_H)
        xz = (self.inner_surface(theta, Z + FD_H, p) - self.inner_surface(theta, Z - FD_H, p)) / (2 * FD_H)
        n = np.cross(xt, xz)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        lam_t = np.linalg.norm(xt, axis=-1) / self.radius
        lam_z = np.linalg.norm(xz, axis=-1)
        return n, lam_t, lam_z

    def membrane_thickness_at(self, theta: np.ndarray, Z: np.ndarray, p: float) -> np.ndarray:
        """Current membrane thickness, mm (incompressible: t0 / (lambda_theta lambda_Z))."""
        _, lt, lz = self._frame(np.asarray(theta, float), np.asarray(Z, float), p)
        return self.membrane_thickness / (lt * lz)

    def outer_surface(self, theta: np.ndarray, Z: np.ndarray, p: float) -> tuple[np.ndarray, np.ndarray]:
        """Printed-surface points (N, 3) and outward unit normals (N, 3) at material (theta, Z).

        In the undeformed state the printed surface is the cylinder of radius R0 + t0.
        """
        theta = np.asarray(theta, float)
        Z = np.asarray(Z, float)
        n, lt, lz = self._frame(theta, Z, p)
        t = self.membrane_thickness / (lt * lz)
        return self.inner_surface(theta, Z, p) + t[..., None] * n, n

    # ----------------------------------------------------------------- volume
    def soil_volume(self, p: float, n_z: int = 96, n_theta: int = 256) -> float:
        """Soil volume (mm^3) inside the inner membrane surface, between the pedestal faces.

        Each horizontal slice at material height Z is the star-shaped region
        ``{c(Z) + r (cos theta, sin theta): r < rho}`` of area ``1/2 int rho^2 dtheta``; the
        volume is ``int A(Z) dz/dZ dZ``.
        """
        zg, wg = np.polynomial.legendre.leggauss(n_z)
        Z = 0.5 * self.height * (zg + 1)
        wz = 0.5 * self.height * wg
        th = 2 * np.pi * np.arange(n_theta) / n_theta
        T, ZZ = np.meshgrid(th, Z)
        zeta = ZZ / self.height
        rho = self.radius + self.bulge_mm * p * self._phi(zeta) * (
            1 + self.bulge_asymmetry * np.cos(T - self.bulge_azimuth)
        )
        area = 0.5 * (rho**2).sum(axis=1) * (2 * np.pi / n_theta)
        k = self.axial_nonuniformity * p
        dz_dZ = self.current_height(p) / self.height * (1 - k * (1 - 2 * Z / self.height))
        return float(np.sum(area * dz_dZ * wz))

    # ----------------------------------------------------------------- sections
    def material_z(self, z: np.ndarray, p: float) -> np.ndarray:
        """Material height Z (mm) of the soil surface at current height ``z`` (mm above the bottom
        face), progress p: the exact inverse of ``z = H g(Z / H0)`` (clipped to the faces)."""
        k = self.axial_nonuniformity * p
        u = np.clip(np.asarray(z, float) / self.current_height(p), 0.0, 1.0)
        return self.height * 2 * u / ((1 - k) + np.sqrt((1 - k) ** 2 + 4 * k * u))  # stable root

    def section_area(self, z: np.ndarray, p: float, n_theta: int = 256) -> np.ndarray:
        """Area (mm^2) of the horizontal soil section at current heights ``z`` (mm), progress p.

        The slice at material height Z is star-shaped about the axis offset ``c(Z)``, of area
        ``1/2 int rho^2 dtheta`` (trapezoidal in theta: spectrally accurate)."""
        zeta = self.material_z(np.atleast_1d(z), p)[:, None] / self.height
        th = 2 * np.pi * np.arange(n_theta) / n_theta
        rho = self.radius + self.bulge_mm * p * self._phi(zeta) * (
            1 + self.bulge_asymmetry * np.cos(th[None, :] - self.bulge_azimuth)
        )
        return 0.5 * (rho**2).sum(axis=1) * (2 * np.pi / n_theta)
