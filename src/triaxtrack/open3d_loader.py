"""Import Open3D without root: its wheel needs ``libusb-1.0.so.0``, which slim machines and
cluster nodes often lack. The ``libusb-package`` wheel ships that library; loading it globally
before Open3D satisfies the dependency without a system package."""

from __future__ import annotations

import ctypes
from types import ModuleType


def import_open3d() -> ModuleType:
    """Open3D, with libusb from the ``libusb-package`` wheel preloaded (RTLD_GLOBAL)."""
    try:
        import libusb_package

        path = libusb_package.get_library_path()
        if path is not None:
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
    except (ImportError, OSError):  # fall back to a system libusb, if any
        pass
    import open3d

    return open3d
