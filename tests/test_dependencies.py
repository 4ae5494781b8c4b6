"""Every declared dependency imports in the project's environment (no system packages needed)."""

from __future__ import annotations

import numpy as np


def test_open3d_imports_without_system_libusb():
    from triaxtrack.open3d_loader import import_open3d

    o3d = import_open3d()
    mesh = o3d.geometry.TriangleMesh.create_box(2.0, 3.0, 4.0)
    assert mesh.is_watertight()
    assert abs(mesh.get_volume() - 24.0) < 1e-9


def test_pycolmap_and_pyav_with_x264_and_x265():
    import av
    import pycolmap

    assert {"libx264", "libx265"} <= set(av.codecs_available)
    rec = pycolmap.Reconstruction()
    assert rec.num_points3D() == 0
    assert np.isfinite(np.linalg.norm(np.eye(3)))
