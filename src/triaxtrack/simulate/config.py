"""What to simulate: :class:`SimulationConfig`, its presets (``PRESETS``), and the frames each
simulated camera records."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from triaxtrack.config_section import field_names, section_dict

VIGNETTING = 0.22  # default relative fall-off of light at the image corners
MAX_TILT_DEG = 30.0  # largest camera_tilt_deg accepted (the specimen leaves the picture well before)


@dataclass(frozen=True)
class SimulationConfig:
    """What to simulate. Lengths mm, times s, angles as named; see config/README.md."""

    cameras: int = 13
    frames: int = 100
    width: int = 1280
    height: int = 720
    fps: float = 15.0
    seed: int = 1
    codec: str = "h264"
    crf: int = 14
    axial_strain: float = 0.05
    bulge_mm: float = 2.0
    shear_mm: float = 0.0
    axial_nonuniformity: float = 0.3  # final k of the deformation: the lower part compresses more
    camera_radius_mm: float = 340.0
    camera_height_mm: float = 72.0
    focal_factor: float = 0.62  # focal length / image width (about 93 degrees across)
    k1: float = -0.3
    k2: float = 0.08
    noise_sigma: float = 1.5
    blur_sigma_px: float = 0.0
    # camera and recorder effects (triaxtrack.footage); all off / today's value by default
    vignetting: float = VIGNETTING  # light fall-off at the image corners (relative)
    light_gradient: float = 0.0  # lamp on one side: the dark side this much darker (relative)
    exposure_drift: float = 0.0  # largest relative exposure-gain change over the test
    exposure: float = 1.0  # the cameras' exposure gain: 1 as lit, 0.3 an under-exposed (dim) picture
    timestamp_overlay: bool = False  # burn a "2026-11-25 14:03:27" date/time into the top-left corner
    camera_tilt_deg: float = 0.0  # each camera's pitch drawn uniformly in +- this, degrees
    occluder_z_mm: tuple[float, float] | None = None  # (z0, z1): a dark band hides the membrane there
    calibration_images: int = 20  # board images per camera (test-folder.md: 10-20); 40 % across image corners
    min_view_cos: float = 0.3
    # the recorder's keyframe interval (a GOP), seconds: a keyframe every round(gop_s x fps)
    # frames counted from the first, whatever the chunk size (issue 17)
    gop_s: float = 2.0
    # the simulated load-frame log's settings (triaxtrack.simulate.loadlog; issue 18): empty, no
    # log; any key (e.g. {clock_offset_s: 1.3}) writes loadframe.csv, see LoadFrameSimulation
    load_frame: dict = field(default_factory=dict)
    # the loading history: knots [u, p] of the progress p (0-1, the deformation's) against the
    # share u (0-1) of the test's duration, linear between; None: p = u (a constant strain rate).
    # E.g. a hold and an unload-reload loop: [[0, 0], [0.3, 0.4], [0.4, 0.4], [0.5, 0.39], ...]
    loading_history: list[list[float]] | None = None
    # per camera (by name): test-clock time of its first frame, a whole number of frames >= 0
    # (the camera started late), and the nominal frame numbers it dropped (triaxtrack.frames)
    start_offset_s: dict[str, float] = field(default_factory=dict)
    dropped_frames: dict[str, list[int]] = field(default_factory=dict)

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> SimulationConfig:
        """Settings from a mapping of field names (config files, the CLI, scene.json).

        The extra key ``preset`` (``clean`` or ``nvr``, see ``PRESETS``) fills in a set of keys
        first; keys given explicitly in ``d`` override it. ValueError naming the key for an
        unknown key or preset, or a value out of range.
        """
        d = apply_preset(section_dict(d, "simulation", (*field_names(SimulationConfig), "preset")))
        if d.get("occluder_z_mm") is not None:
            z = d["occluder_z_mm"]
            if isinstance(z, (str, bytes)) or not hasattr(z, "__len__") or len(z) != 2:
                raise ValueError(f"occluder_z_mm must be null or [z0, z1] in mm, not {z!r}")
            try:
                d = {**d, "occluder_z_mm": (float(z[0]), float(z[1]))}
            except (TypeError, ValueError):
                raise ValueError(f"occluder_z_mm must be null or [z0, z1] in mm, not {z!r}") from None
        if d.get("loading_history") is not None:
            d = {**d, "loading_history": check_loading_history(d["loading_history"])}
        cfg = SimulationConfig(**d)
        _check_effects(cfg)
        if cfg.codec not in ("h264", "h265"):
            raise ValueError(f"codec must be h264 or h265, not {cfg.codec!r}")
        if isinstance(cfg.gop_s, bool) or not isinstance(cfg.gop_s, (int, float)) or not cfg.gop_s > 0:
            raise ValueError(f"gop_s must be a number of seconds > 0, not {cfg.gop_s!r}")
        if cfg.frames < 2 or cfg.cameras < 1:
            raise ValueError("a simulated test needs at least 2 frames and 1 camera")
        names = set(camera_names(cfg.cameras))
        for key in ("start_offset_s", "dropped_frames"):
            unknown_cams = set(getattr(cfg, key)) - names
            if unknown_cams:
                raise ValueError(f"{key}: no camera {sorted(unknown_cams)} among cam01..cam{cfg.cameras:02d}")
        for cam in names:
            recorded_frames(cfg, cam)  # checks offsets and drops
        return cfg


# Named sets of settings for `preset` (SimulationConfig.from_dict, `triaxtrack simulate --preset`).
# nvr: a 4K surveillance camera recorded by a network video recorder: H.265 at a low bitrate,
# sensor noise, a soft fixed-focus lens, a lamp on one side, a wide-angle lens's vignetting, the
# recorder's burned-in date/time and a slowly drifting exposure. Its lens blur is NVR_LENS_BLUR_PX
# at every image size (the 0.7-1.2 px of a soft fixed-focus lens). At 1280 x 720 it
# nearly closes the 1 px gaps between the membrane's large dots: ../shared/tools/check_sim.py,
# which thresholds, then matched 69 % of the membrane's on a 720p test (2026-11-25).
NVR_LENS_BLUR_PX = 1.0
PRESETS: dict[str, dict] = {
    "clean": {},
    "nvr": {
        "codec": "h265",
        "crf": 28,
        "noise_sigma": 4.0,
        "blur_sigma_px": NVR_LENS_BLUR_PX,
        "light_gradient": 0.3,
        "vignetting": 0.35,
        "timestamp_overlay": True,
        "exposure_drift": 0.03,
    },
}


MAX_EXPOSURE = 2.0  # simulation.exposure: brighter saturates the white surfaces


def apply_preset(d: dict) -> dict:
    """A copy of settings ``d`` with its ``preset`` (if any) expanded: the preset's keys
    (``PRESETS``), then ``d``'s own keys over them; the ``preset`` key itself is removed."""
    d = dict(d)
    name = d.pop("preset", None)
    if name is None:
        return d
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)}, not {name!r}")
    return {**PRESETS[name], **d}


def _check_effects(cfg: SimulationConfig) -> None:
    """ValueError naming the key for a camera or recorder effect out of range."""
    for key in ("vignetting", "light_gradient", "exposure_drift"):
        v = getattr(cfg, key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < 1:
            raise ValueError(f"{key} must be a number in [0, 1), not {v!r}")
    e = cfg.exposure
    if isinstance(e, bool) or not isinstance(e, (int, float)) or not 0 < e <= MAX_EXPOSURE:
        raise ValueError(f"exposure must be a number in (0, {MAX_EXPOSURE}], not {e!r}")
    if not isinstance(cfg.timestamp_overlay, bool):
        raise ValueError(f"timestamp_overlay must be true or false, not {cfg.timestamp_overlay!r}")
    t = cfg.camera_tilt_deg
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not 0 <= t <= MAX_TILT_DEG:
        raise ValueError(f"camera_tilt_deg must be a number in [0, {MAX_TILT_DEG}] degrees, not {t!r}")
    z = cfg.occluder_z_mm
    if z is not None and not (np.isfinite(z).all() and z[0] < z[1]):
        raise ValueError(f"occluder_z_mm must be [z0, z1] with z0 < z1, mm, not {list(z)}")


def check_loading_history(knots) -> list[list[float]]:
    """``knots`` as a list of ``[u, p]`` floats (ValueError naming ``loading_history`` unless
    u rises strictly from 0 to 1 and every p is in [0, 1])."""
    msg = "loading_history must be null or a list of [u, p] knots, u rising strictly from 0 to 1, p in [0, 1]"
    try:
        arr = np.asarray(knots, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{msg}, not {knots!r}") from None
    if (
        arr.ndim != 2
        or arr.shape[1] != 2
        or len(arr) < 2
        or not np.isfinite(arr).all()
        or arr[0, 0] != 0
        or arr[-1, 0] != 1
        or np.any(np.diff(arr[:, 0]) <= 0)
        or np.any((arr[:, 1] < 0) | (arr[:, 1] > 1))
    ):
        raise ValueError(f"{msg}, not {knots!r}")
    return arr.tolist()


def loading_progress(cfg: SimulationConfig, time_s: float | np.ndarray) -> np.ndarray:
    """Loading progress p (0-1) at test-clock times ``time_s`` (s; frame k at k / fps): the share
    of the test's duration ``u = time_s fps / (frames - 1)``, clipped to [0, 1] (before the first
    frame and after the last the specimen rests), through ``loading_history`` (p = u without one).
    """
    u = np.clip(np.asarray(time_s, float) * cfg.fps / (cfg.frames - 1), 0.0, 1.0)
    if cfg.loading_history is None:
        return u
    knots = np.asarray(cfg.loading_history, float)
    return np.interp(u, knots[:, 0], knots[:, 1])


def camera_names(n: int) -> list[str]:
    return [f"cam{i + 1:02d}" for i in range(n)]


def recorded_frames(cfg: SimulationConfig, camera: str) -> np.ndarray:
    """The test frames (sorted int64) that a simulated camera recorded.

    A camera with ``start_offset_s`` = m / fps starts recording at test frame m and records to
    the end of the test; its nominal frame n (0-based, drops counted) is test frame n + m, and
    the nominal frames in ``dropped_frames`` are left out. ValueError for an offset that is
    negative or not a whole number of frames, or drops outside the recording.
    """
    offset = float(cfg.start_offset_s.get(camera, 0.0))
    m = round(offset * cfg.fps)
    if m < 0 or abs(offset * cfg.fps - m) > 1e-6:
        raise ValueError(
            f"start_offset_s of {camera}: {offset} s is not a whole number of frames >= 0 at "
            f"{cfg.fps} fps (the simulator renders test frames only)"
        )
    drops = [int(n) for n in cfg.dropped_frames.get(camera, [])]
    n_nominal = cfg.frames - m
    if len(set(drops)) != len(drops) or any(not 0 <= n < n_nominal for n in drops):
        raise ValueError(
            f"dropped_frames of {camera}: {drops} must be distinct nominal frames 0..{n_nominal - 1}"
        )
    n = np.setdiff1d(np.arange(n_nominal, dtype=np.int64), np.asarray(drops, np.int64))
    if len(n) == 0:
        raise ValueError(f"{camera} records no frame (start_offset_s and dropped_frames)")
    return n + m


def gop_frames(cfg: SimulationConfig) -> int:
    """The recorder's keyframe interval in frames: ``round(gop_s x fps)``, at least 1."""
    return max(1, round(cfg.gop_s * cfg.fps))


def render_segments(frames: int, chunk_size: int, gop: int) -> list[tuple[int, int]]:
    """The test frames ``(start, stop)`` (stop exclusive) of each separately encoded video
    segment of a simulated camera, in order, covering ``0 .. frames - 1``.

    A recorder puts a keyframe on every multiple of ``gop`` frames and nowhere else, while a
    segment joined by stream copy (:func:`triaxtrack.video.concat_videos`) must start with one:
    so segments start on the GOP grid, ``chunk_size`` rounded up to a whole number of GOPs long
    (the last one shorter). Every ``chunk_size`` that is a multiple of ``gop`` gives the
    workflow's chunks themselves.
    """
    if frames < 1 or chunk_size < 1 or gop < 1:
        raise ValueError(f"frames, chunk_size and gop must be >= 1, not {frames}, {chunk_size}, {gop}")
    size = -(-chunk_size // gop) * gop
    return [(start, min(start + size, frames)) for start in range(0, frames, size)]
