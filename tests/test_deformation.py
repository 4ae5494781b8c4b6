"""Specimen kinematics: exact volumes and material-point behaviour."""

from __future__ import annotations

import numpy as np
import pytest

from triaxtrack.deformation import Deformation


def test_undeformed_volume_is_pi_r2_h():
    d = Deformation(radius=35.55, height=142.2)
    v = d.soil_volume(0.0)
    assert v == pytest.approx(np.pi * 35.55**2 * 142.2, rel=1e-6)


def test_rigid_shear_and_compression_volume():
    # no bulge: a sheared, shortened cylinder has volume pi r^2 h(p)
    d = Deformation(bulge_mm=0.0, shear_mm=4.0, axial_strain=0.1, axial_nonuniformity=0.3)
    assert d.soil_volume(1.0) == pytest.approx(np.pi * d.radius**2 * d.height * 0.9, rel=1e-9)


def test_volume_against_mesh_divergence():
    """Quadrature volume equals the volume of a fine closed mesh of the inner surface."""
    d = Deformation(axial_strain=0.1, bulge_mm=4.0, shear_mm=2.0)
    nt, nz = 720, 400
    th = 2 * np.pi * np.arange(nt) / nt
    Z = np.linspace(0, d.height, nz)
    T, ZZ = np.meshgrid(th, Z)
    P = d.inner_surface(T.ravel(), ZZ.ravel(), 1.0).reshape(nz, nt, 3)
    vol = 0.0
    for i in range(nz - 1):
        a, b = P[i], P[i + 1]
        a1, b1 = np.roll(a, -1, axis=0), np.roll(b, -1, axis=0)
        for tri in ((a, a1, b1), (a, b1, b)):
            vol += np.einsum("ij,ij->i", tri[0], np.cross(tri[1], tri[2])).sum() / 6
    # caps: flat discs at z = 0 and z = H(p) about their centres
    for ring, sign in ((P[0], -1), (P[-1], 1)):
        c = ring.mean(axis=0)
        r1 = np.roll(ring, -1, axis=0)
        vol += sign * np.einsum("ij,ij->i", np.broadcast_to(c, ring.shape), np.cross(ring, r1)).sum() / 6
    # the fine mesh is chordal: its deficit shrinks as 1/n^2, so compare at 2e-4
    assert vol == pytest.approx(d.soil_volume(1.0), rel=2e-4)


def test_membrane_thickness_follows_stretch_and_stays_outside_soil():
    bulge_only = Deformation(axial_strain=0.0, axial_nonuniformity=0.0, bulge_mm=4.0)
    th, Z = np.array([0.6]), np.array([0.35 * bulge_only.height])
    assert bulge_only.membrane_thickness_at(th, Z, 1.0)[0] < 0.3  # stretched: thinner
    squashed = Deformation(axial_strain=0.1, bulge_mm=0.0, axial_nonuniformity=0.0)
    assert squashed.membrane_thickness_at(th, Z, 1.0)[0] == pytest.approx(0.3 / 0.9, rel=1e-6)
    d = Deformation(axial_strain=0.1, bulge_mm=4.0)
    t = d.membrane_thickness_at(th, Z, 1.0)[0]
    outer, n = d.outer_surface(th, Z, 1.0)
    inner = d.inner_surface(th, Z, 1.0)
    assert np.linalg.norm(outer - inner) == pytest.approx(t, rel=1e-9)
    assert (np.hypot(outer[:, 0], outer[:, 1]) > np.hypot(inner[:, 0], inner[:, 1])).all()


def test_lower_part_bulges_more():
    d = Deformation()
    th = np.zeros(2)
    Z = np.array([0.3, 0.7]) * d.height
    r = np.hypot(*d.inner_surface(th, Z, 1.0)[:, :2].T)
    assert r[0] > r[1]
