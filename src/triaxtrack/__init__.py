"""triaxtrack: continuous 3-D deformation of triaxial soil specimens from multi-camera video.

Conventions used throughout the package:

* lengths in millimetres, angles in radians, times in seconds;
* 3-D points in the cell frame (``target-kit.md``): origin at the centre of the top face of
  the bottom pedestal, +z up the cell axis, +x towards bottom-pedestal coded target 17;
* pixel coordinates follow OpenCV: the centre of the top-left pixel is (0, 0);
* cameras follow OpenCV: ``x_cam = R @ x_cell + t``.
"""

from pathlib import Path

__version__ = "0.1.0"


def numba_cache_dir(package: Path, cache_home: Path) -> Path:
    """The directory under ``cache_home`` for numba's compiled kernels of the package at
    ``package``, named after the content of every module of it that uses numba.

    numba (``cache=True``) checks only a kernel's own file for changes: a kernel that calls one
    in another module (``window`` into ``window_rows``) ran its old compiled code after that
    module alone changed. Keyed by all the kernel modules' content, any change compiles afresh."""
    import hashlib

    digest = hashlib.sha1()
    for path in sorted(package.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            digest.update(path.relative_to(package).as_posix().encode() + b"\0" + text)
    return cache_home / "triaxtrack" / "numba" / digest.hexdigest()[:16]


def _set_numba_cache() -> None:
    """Point numba's cache at :func:`numba_cache_dir` (under ``XDG_CACHE_HOME`` or
    ``~/.cache``) unless the user chose one (``NUMBA_CACHE_DIR``)."""
    import os
    import sys

    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    os.environ["NUMBA_CACHE_DIR"] = str(numba_cache_dir(Path(__file__).resolve().parent, home))
    if "numba" in sys.modules:  # numba reads it when imported: set it there too
        sys.modules["numba"].config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]


_set_numba_cache()
