"""triaxtrack: continuous 3-D deformation of triaxial soil specimens from multi-camera video.

Conventions used throughout the package:

* lengths in millimetres, angles in radians, times in seconds;
* 3-D points in the cell frame (``target-kit.md``): origin at the centre of the top face of
  the bottom pedestal, +z up the cell axis, +x towards bottom-pedestal coded target 17;
* pixel coordinates follow OpenCV: the centre of the top-left pixel is (0, 0);
* cameras follow OpenCV: ``x_cam = R @ x_cell + t``.
"""

__version__ = "0.1.0"
