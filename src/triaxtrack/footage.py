"""Camera and recorder effects of simulated footage: light, exposure, the burned-in timestamp.

Everything here acts on a rendered grey image (float, grey levels) and is pure: inputs are never
modified. Pixels follow OpenCV: the centre of the top-left pixel is (0, 0), x to the right, y
down. The per-camera random choices (direction of the light gradient, shape of the exposure
drift) are seeded by the test's seed and the camera's name only, so they never depend on the
other settings and a clean render draws no extra random numbers.

What a surveillance recorder (NVR) adds, in the order the simulator applies it (after the scene
is drawn, see :meth:`triaxtrack.simulate.CameraRenderer.render`):

1. light: vignetting of the wide-angle lens times a linear gradient from a lamp on one side
   (:func:`light_field`), times the slowly drifting exposure gain (:func:`exposure_gain`);
2. lens blur (a Gaussian, in the simulator);
3. the date/time text burned into the top-left corner (:func:`draw_timestamp`), white with a
   dark outline, as the recorder draws it over the camera's picture;
4. sensor noise, rounding to 8 bits, then the codec.
"""

from __future__ import annotations

import zlib
from datetime import datetime, timedelta
from functools import lru_cache

import cv2
import numpy as np

# -- timestamp overlay (NVR style). Sizes are relative to the image height so that the text
# looks the same at 720p and 4K: about 20 px tall at 720p, 60 px at 2160p
OVERLAY_START = datetime(2026, 11, 25, 14, 3, 27)  # wall-clock time of test frame 0
OVERLAY_FORMAT = "%Y-%m-%d %H:%M:%S"  # "2026-11-25 14:03:27"
OVERLAY_TEXT_HEIGHT_REL = 0.028  # digit height / image height
OVERLAY_MARGIN_REL = 0.02  # gap between the text box and the image's top and left edges / height
OVERLAY_STROKE_REL = 0.1  # text stroke width / digit height (Hershey simplex at normal weight)
OVERLAY_OUTLINE_REL = 0.08  # dark outline on each side of a stroke / digit height
OVERLAY_FONT = cv2.FONT_HERSHEY_SIMPLEX
OVERLAY_FONT_DIGIT_PX = 21.0  # digit height of OVERLAY_FONT at fontScale 1, pixels
GREY_OVERLAY_TEXT = 250.0  # near-white text
GREY_OVERLAY_OUTLINE = 15.0  # near-black outline
# every digit of OVERLAY_FONT has the same advance, so the union of these templates holds every
# date and time the overlay can show
_OVERLAY_TEMPLATES = tuple(f"{d * 4}-{d * 2}-{d * 2} {d * 2}:{d * 2}:{d * 2}" for d in "0123456789")

# -- seeding: per camera, the seed sequence [seed, crc32(camera), *stream]: a frame's noise has
# the stream (frame,), the calibration images (7,) and (11,); the effects' streams have two
# elements, so they never coincide with a frame's
LIGHT_STREAM = (0, 1)


def camera_rng(seed: int, camera: str, stream: tuple[int, ...]) -> np.random.Generator:
    """A generator seeded by the test's seed, the camera's name and a stream (see above)."""
    return np.random.default_rng([seed, zlib.crc32(camera.encode()), *stream])


# ---------------------------------------------------------------- light and exposure
def vignetting_field(width: int, height: int, cx: float, cy: float, vignetting: float) -> np.ndarray:
    """(height, width) relative light ``1 - vignetting r^2`` of a wide-angle lens.

    ``r`` is the distance from the principal point (``cx``, ``cy``, pixels) over the half
    diagonal of the image, so ``vignetting`` is the fall-off at the image corners (0.22: 22 %
    darker there than at the centre).
    """
    yy, xx = np.mgrid[0:height, 0:width]
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / ((width / 2) ** 2 + (height / 2) ** 2)
    return 1 - vignetting * r2


def gradient_field(width: int, height: int, gradient: float, direction_rad: float) -> np.ndarray:
    """(height, width) relative light of a lamp on one side: 1 on the bright side falling
    linearly to ``1 - gradient`` on the dark side.

    ``direction_rad`` points from the bright side to the dark side, in the image (0: the right
    edge is darkest; pi / 2: the bottom edge). The extremes are the image's corner pixels (or
    whole edges) farthest either way along that direction, so the brightest and darkest
    pixels differ by exactly ``gradient`` (0.3: one side 30 % darker than the other).
    """
    d = np.array([np.cos(direction_rad), np.sin(direction_rad)])
    corners = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], float)
    s_corner = corners @ d
    lo, span = s_corner.min(), np.ptp(s_corner)
    yy, xx = np.mgrid[0:height, 0:width]
    s = (xx * d[0] + yy * d[1] - lo) / span
    return 1 - gradient * s


def gradient_direction(seed: int, camera: str) -> float:
    """Seeded direction (radians, image frame: 0 = towards +x) of a camera's light gradient:
    where the lamp throws less light, as seen by this camera."""
    return float(camera_rng(seed, camera, LIGHT_STREAM).uniform(0, 2 * np.pi))


def exposure_gain(progress: float, drift: float, seed: int, camera: str) -> float:
    """Exposure gain of a camera at loading ``progress`` (0 first frame, 1 last frame).

    ``1 + s drift u(p)`` with ``u(p) = (1 - a) (1 - cos(pi p)) / 2 + a sin(pi p)``: a smooth
    slow drift that starts at 1, never departs from 1 by more than ``drift``, and ends at
    ``1 +- drift (1 - a)``. The sign ``s`` (brighter or darker) and the hump ``a`` in [0, 0.5)
    are seeded per camera.
    """
    rng = camera_rng(seed, camera, LIGHT_STREAM)
    rng.uniform(0, 2 * np.pi)  # the gradient direction comes first in this stream
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    hump = rng.uniform(0, 0.5)
    u = (1 - hump) * (1 - np.cos(np.pi * progress)) / 2 + hump * np.sin(np.pi * progress)
    return float(1 + sign * drift * u)


# ---------------------------------------------------------------- timestamp overlay
def timestamp_text(frame: int, fps: float) -> str:
    """The recorder's date and time at test frame ``frame`` (whole seconds of test time after
    ``OVERLAY_START``), e.g. ``"2026-11-25 14:03:27"``."""
    seconds = int(np.floor(frame / fps + 1e-9))  # 1e-9: frame k at exactly n s shows n
    return (OVERLAY_START + timedelta(seconds=seconds)).strftime(OVERLAY_FORMAT)


@lru_cache(maxsize=16)
def _overlay_layout(width: int, height: int) -> tuple[float, int, int, tuple[int, int]]:
    """(fontScale, stroke px, outline stroke px, text origin (x, y) px) for an image size."""
    digit_px = OVERLAY_TEXT_HEIGHT_REL * height
    scale = digit_px / OVERLAY_FONT_DIGIT_PX
    stroke = max(1, round(OVERLAY_STROKE_REL * digit_px))
    outline = stroke + 2 * max(1, round(OVERLAY_OUTLINE_REL * digit_px))
    margin = round(OVERLAY_MARGIN_REL * height)
    (_, text_h), _ = cv2.getTextSize(_OVERLAY_TEMPLATES[0], OVERLAY_FONT, scale, outline)
    return scale, stroke, outline, (margin, margin + text_h)


def _overlay_masks(width: int, height: int, text: str) -> tuple[np.ndarray, np.ndarray]:
    """Anti-aliased (height, width) alpha in [0, 1] of the outline and of the text strokes."""
    scale, stroke, outline, org = _overlay_layout(width, height)
    m = np.zeros((height, width), np.uint8)
    cv2.putText(m, text, org, OVERLAY_FONT, scale, 255, stroke, cv2.LINE_AA)
    # the outline: the strokes grown on each side (putText's thickness is not a reliable width)
    reach = (outline - stroke) // 2
    ring = cv2.dilate(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1)))
    return ring / 255.0, m / 255.0


@lru_cache(maxsize=16)
def overlay_box(width: int, height: int) -> tuple[int, int, int, int]:
    """Pixel box ``(x0, y0, x1, y1)``, inclusive, that every timestamp the overlay can show
    lies in (text and outline), for an image of ``width`` x ``height`` pixels."""
    union = np.zeros((height, width), bool)
    for text in _OVERLAY_TEMPLATES:
        union |= _overlay_masks(width, height, text)[0] > 0
    rows, cols = np.flatnonzero(union.any(axis=1)), np.flatnonzero(union.any(axis=0))
    return int(cols[0]), int(rows[0]), int(cols[-1]), int(rows[-1])


def draw_timestamp(image: np.ndarray, text: str) -> np.ndarray:
    """A copy of a float grey ``image`` with ``text`` burned into its top-left corner: white
    (``GREY_OVERLAY_TEXT``) strokes over a dark (``GREY_OVERLAY_OUTLINE``) outline, drawn with
    ``cv2.putText`` (anti-aliased), sized to the image height; inside :func:`overlay_box`."""
    h, w = image.shape
    edge, ink = _overlay_masks(w, h, text)
    out = image + edge * (GREY_OVERLAY_OUTLINE - image)
    return out + ink * (GREY_OVERLAY_TEXT - out)


def boxes_overlap(boxes: np.ndarray, box: tuple[int, int, int, int], margin: float) -> np.ndarray:
    """Which image boxes (N, 4: u0, v0, u1, v1, pixels, continuous) come within ``margin``
    pixels of the pixel box ``box`` (x0, y0, x1, y1, inclusive pixel indices: pixel i covers
    i - 0.5 .. i + 0.5)."""
    x0, y0, x1, y1 = box
    b = np.asarray(boxes, float).reshape(-1, 4)
    return (
        (b[:, 0] - margin <= x1 + 0.5)
        & (b[:, 2] + margin >= x0 - 0.5)
        & (b[:, 1] - margin <= y1 + 0.5)
        & (b[:, 3] + margin >= y0 - 0.5)
    )
