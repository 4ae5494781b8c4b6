"""A physically exact simulated triaxial test, written as a test folder (``test-folder.md``).

The scene: the kit's printed shapes on four cylinders (cell wall in air; pedestals and membrane
in water behind the acrylic wall), a ring of wide-angle cameras (OpenCV pinhole +
Brown-Conrady distortion), and a specimen that deforms as :class:`Deformation` says.

Rendering is forward and exact at every polygon vertex: a vertex in air is projected with
``cv2.projectPoints``; a vertex in water with :func:`project_water` (Snell's law at both walls,
solved until the point is within 1e-6 mm of its refracted ray, about 3e-6 px). Polygons are
filled with exact area coverage (:mod:`triaxtrack.raster`),
so a dot's rendered centroid differs from the exact image of its centre only by the physical
bias of perspective and refraction across the dot (measured by the tests). What is drawn,
back to front: background, pedestals (sides and the visible end faces), their white labels and
black ink, the membrane, its dots, the optional occluder band (``occluder_z_mm``), then the white
bands and black ink on the cell's outer wall. Camera and recorder effects follow
(:mod:`triaxtrack.footage`: light, exposure, blur, the timestamp overlay, noise; the ``nvr``
preset turns them on), and the truth lists only the targets nothing hides
(:meth:`CameraRenderer._observations`).
Faces turned away from the camera are culled (the specimen and pedestals are convex). Not
drawn: the backs of the cell's far-side white bands seen through the water (for the default
ring they would show above the top pedestal, near the top of the image, where the render leaves
plain background; no target is measured there), shadows and reflections. Every camera must sit
between the pedestal faces for the whole test (checked), so the pedestals never hide the
membrane.

Frame ``k`` has time ``k / fps`` s and loading progress ``p = k / (frames - 1)``.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import yaml

from triaxtrack import footage
from triaxtrack.centroid import local_centroid
from triaxtrack.deformation import Deformation
from triaxtrack.kit import (
    ShapeSet,
    board_corners_mm,
    board_polygons_mm,
    load_kit_design,
    printed_shapes,
    surface_by_name,
    target_table,
)
from triaxtrack.optics import Camera, CellOptics, cell_optics, project_air, project_water, read_cameras
from triaxtrack.raster import paint_into
from triaxtrack.tables import OBSERVATIONS, POINTS, VOLUME, read_table, write_table
from triaxtrack.video import VideoWriter

# grey levels of the materials (8-bit, before lighting and noise)
GREY_BACKGROUND = 40.0
GREY_PEDESTAL_SIDE = 115.0
GREY_PEDESTAL_FACE = 95.0
GREY_MEMBRANE = 195.0
GREY_LABEL = 230.0
GREY_INK = 22.0
VIGNETTING = 0.22  # default relative fall-off of light at the image corners
GREY_OCCLUDER = 70.0  # the dark-grey band of `occluder_z_mm` (a strap or a shadowing bar)
# tessellation of the untextured surfaces (their outlines only; dots are drawn exactly)
MEMBRANE_QUADS = (96, 48)  # (theta, Z)
PEDESTAL_QUADS = 72
# placement jitter of the simulated cameras (uniform +- these)
JITTER_ANGLE_DEG = 1.5
JITTER_POSITION_MM = 3.0
JITTER_ROTATION_DEG = 0.7
JITTER_FOCAL_REL = 0.01
JITTER_PRINCIPAL_REL = 0.005
JITTER_K1, JITTER_K2, JITTER_P = 0.02, 0.01, 3e-4
TILT_STREAM = (0, 2)  # the per-camera seed stream of `camera_tilt_deg` (footage.camera_rng)
MAX_TILT_DEG = 30.0  # largest camera_tilt_deg accepted (the specimen leaves the picture well before)
OCCLUDER_QUADS = 192  # theta tessellation of the occluder band (chords: < 0.1 px from the exact edge)
OCCLUDER_ROW_MM = 3.0  # the band is drawn in rows of at most this height (follows the bulge)
OCCLUDER_NEWTON_STEPS = 3  # fixed-point steps from the soil-surface height to the printed surface's
EDGE_MARGIN_PX = 2.0  # a target is "seen" only if its whole image is this far inside the frame
OCCLUSION_TOL = 0.01  # coverage by a cell band above which a target behind it is hidden
CHECK_SAMPLE = 300  # dots per surface, camera and frame measured by check_simulation
SUBROWS_INK = 16  # y sampling of printed ink: keeps rendered centroids exact to < 0.005 px
SUBROWS_PLAIN = 4  # y sampling of outlines and white labels (no measurement relies on them)
# calibration-board poses (board_poses). Strong tilts in every direction and boards reaching the
# image edges pin down the focal length and the distortion; but a whole board cannot reach the
# image corners of a wide-angle lens (with k1 = -0.3 no corner of a whole 10 x 7 board came
# closer than 125-235 px to them, and k1, k2, k3 extrapolated there: undistortion map off by
# 0.26 px, median camera, and 0.85 px, worst, on the demo), so some boards run off the image
# across its corners, as a lab photographs them for a wide-angle camera. With these poses (20
# images, the kit's 16 x 11 board) the map is off by 0.018-0.026 px (median camera) and
# 0.039-0.051 px (worst) on the demo and the three validation tests
BOARD_TILT_DEG = (30.0, 55.0)  # tilt about an in-plane axis of random direction
BOARD_ROLL_DEG = 20.0  # in-plane rotation, +-
BOARD_DISTANCE_MM = (180.0, 320.0)  # whole board: its centre from the camera, before it is shifted
BOARD_MAX_VIEW_DEG = 60.0  # largest angle between the board's normal and the line of sight
BOARD_EDGE_PX = 12.0  # gap left between the sheet's image and the image edge it is pushed to
BOARD_SHIFT_STEPS = 4  # shift iterations (the distortion makes one step inexact)
# where each whole board goes, in turn: (-1, 0, 1) = left / centre / right, top / centre / bottom
BOARD_ANCHORS = ((-1, -1), (1, 1), (1, -1), (-1, 1), (0, 0), (0, -1), (1, 0), (0, 1), (-1, 0))
# boards across an image corner: BOARD_CORNER_SHARE of the images (a multiple of 4, one per image
# corner in turn, none below 10 images); one inner corner of the board, picked at random, lands
# BOARD_CORNER_INSET_PX from both edges at the image corner, and at least BOARD_CORNER_MIN_SEEN
# inner corners, in BOARD_CORNER_MIN_LINES rows and columns or more, lie BOARD_CORNER_SEEN_PX or
# more inside the image (a thin strip of the board is of little use)
BOARD_CORNER_SHARE = 0.4
BOARD_CORNER_INSET_PX = 10.0
BOARD_CORNER_DISTANCE_MM = (150.0, 260.0)  # anchor corner from the camera, before it is shifted
BOARD_CORNER_MIN_SEEN = 30
BOARD_CORNER_MIN_LINES = 4
BOARD_CORNER_SEEN_PX = 12.0
BOARD_CORNER_ORDER = ((-1, -1), (1, 1), (1, -1), (-1, 1))  # image corners, (left/right, top/bottom)
BOARD_MAX_TRIES = 5000  # random poses tried before giving up


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
    timestamp_overlay: bool = False  # burn a "2026-11-25 14:03:27" date/time into the top-left corner
    camera_tilt_deg: float = 0.0  # each camera's pitch drawn uniformly in +- this, degrees
    occluder_z_mm: tuple[float, float] | None = None  # (z0, z1): a dark band hides the membrane there
    calibration_images: int = 20  # board images per camera (test-folder.md: 10-20); 40 % across image corners
    min_view_cos: float = 0.3
    # per camera (by name): test-clock time of its first frame, a whole number of frames >= 0
    # (the camera started late), and the nominal frame numbers it dropped (triaxtrack.frames)
    start_offset_s: dict[str, float] = field(default_factory=dict)
    dropped_frames: dict[str, list[int]] = field(default_factory=dict)

    @staticmethod
    def from_dict(d: dict) -> SimulationConfig:
        """Settings from a mapping of field names (config files, the CLI, scene.json).

        The extra key ``preset`` (``clean`` or ``nvr``, see ``PRESETS``) fills in a set of keys
        first; keys given explicitly in ``d`` override it. ValueError naming the key for an
        unknown key or preset, or a value out of range.
        """
        d = apply_preset(d)
        known = {f.name for f in fields(SimulationConfig)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(
                f"unknown simulation settings: {sorted(unknown)}; known: {sorted(known | {'preset'})}"
            )
        if d.get("occluder_z_mm") is not None:
            z = d["occluder_z_mm"]
            if isinstance(z, (str, bytes)) or not hasattr(z, "__len__") or len(z) != 2:
                raise ValueError(f"occluder_z_mm must be null or [z0, z1] in mm, not {z!r}")
            try:
                d = {**d, "occluder_z_mm": (float(z[0]), float(z[1]))}
            except (TypeError, ValueError):
                raise ValueError(f"occluder_z_mm must be null or [z0, z1] in mm, not {z!r}") from None
        cfg = SimulationConfig(**d)
        _check_effects(cfg)
        if cfg.codec not in ("h264", "h265"):
            raise ValueError(f"codec must be h264 or h265, not {cfg.codec!r}")
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
    if not isinstance(cfg.timestamp_overlay, bool):
        raise ValueError(f"timestamp_overlay must be true or false, not {cfg.timestamp_overlay!r}")
    t = cfg.camera_tilt_deg
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not 0 <= t <= MAX_TILT_DEG:
        raise ValueError(f"camera_tilt_deg must be a number in [0, {MAX_TILT_DEG}] degrees, not {t!r}")
    z = cfg.occluder_z_mm
    if z is not None and not (np.isfinite(z).all() and z[0] < z[1]):
        raise ValueError(f"occluder_z_mm must be [z0, z1] with z0 < z1, mm, not {list(z)}")


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


def deformation_for(cfg: SimulationConfig, design: dict) -> Deformation:
    s = design["specimen"]
    return Deformation(
        radius=s["diameter"] / 2,
        height=s["height"],
        membrane_thickness=s["membrane_thickness"],
        axial_strain=cfg.axial_strain,
        bulge_mm=cfg.bulge_mm,
        shear_mm=cfg.shear_mm,
        axial_nonuniformity=cfg.axial_nonuniformity,
    )


def progress(frame: int, frames: int) -> float:
    """Loading progress of a frame: 0 at the first, 1 at the last (constant strain rate)."""
    return frame / (frames - 1)


# ---------------------------------------------------------------- the scene
@dataclass
class Scene:
    """Everything needed to render any frame of a simulated test."""

    name: str
    cfg: SimulationConfig
    design: dict
    table: pd.DataFrame
    shapes: list[ShapeSet]
    cameras: dict[str, Camera]
    deformation: Deformation
    cell: CellOptics


def load_scene(test_dir: str | Path) -> Scene:
    test_dir = Path(test_dir)
    scene = json.loads((test_dir / "truth" / "scene.json").read_text())
    cfg = SimulationConfig.from_dict(scene["simulation"])
    design = load_kit_design(test_dir / "kit")
    table = target_table(design)
    return Scene(
        name=scene["name"],
        cfg=cfg,
        design=design,
        table=table,
        shapes=printed_shapes(design, table),
        cameras=read_cameras(test_dir / "truth" / "cameras.json"),
        deformation=Deformation(**scene["deformation"]),
        cell=cell_optics(design),
    )


def make_scene(cfg: SimulationConfig, kit_dir: str | Path, test_dir: str | Path, name: str) -> None:
    """Write the static part of a simulated test folder.

    ``test.yaml``, ``kit/`` (a copy of the kit export), ``truth/scene.json`` (how to rebuild
    the scene), ``truth/cameras.json`` and ``truth/volume.parquet``. Videos, calibration
    images and the per-target truth are written by :func:`render_chunk`,
    :func:`render_calibration` and :func:`finish_truth`.
    """
    test_dir = Path(test_dir)
    (test_dir / "truth").mkdir(parents=True, exist_ok=True)
    if Path(kit_dir).resolve() != (test_dir / "kit").resolve():
        shutil.copytree(kit_dir, test_dir / "kit", dirs_exist_ok=True, ignore=shutil.ignore_patterns(".*"))
    design = load_kit_design(test_dir / "kit")
    deformation = deformation_for(cfg, design)
    cams = make_cameras(cfg)
    lowest_top = deformation.current_height(1.0)  # the top cap at the end of the test
    for cam in cams:
        if not 0 < cam.center[2] < lowest_top:
            raise ValueError(
                f"camera {cam.name} at z = {cam.center[2]:.1f} mm is not between the pedestal faces "
                f"(0 and {lowest_top:.1f} mm at the end of loading): lower camera_height_mm"
            )
    (test_dir / "test.yaml").write_text(yaml.safe_dump({
        "name": name,
        "fps": float(cfg.fps),
        "frames": int(cfg.frames),
        "cameras": [_test_yaml_camera(cfg, c.name) for c in cams],
        "kit": "kit",
        "simulated": True,
    }, sort_keys=False))  # fmt: skip
    (test_dir / "truth" / "scene.json").write_text(json.dumps({
        "name": name,
        "simulation": asdict(cfg),
        "deformation": asdict(deformation),
        "notes": "axial_strain = (H0 - H) / H0 and volumetric_strain = (V0 - V) / V0, "
                 "compression positive; volume = soil inside the membrane's inner surface, "
                 "between the pedestal faces",
    }, indent=2))  # fmt: skip
    (test_dir / "truth" / "cameras.json").write_text(
        json.dumps({"cameras": {c.name: c.to_json() for c in cams}}, indent=2)
    )
    write_table(truth_volume(cfg, deformation), test_dir / "truth" / "volume.parquet", VOLUME)


def _test_yaml_camera(cfg: SimulationConfig, camera: str) -> str | dict:
    """A camera's test.yaml entry: its name, or a mapping with its offset and drops if any."""
    entry: dict = {"name": camera}
    if camera in cfg.start_offset_s:
        entry["start_offset_s"] = float(cfg.start_offset_s[camera])
    if cfg.dropped_frames.get(camera):
        entry["dropped_frames"] = sorted(int(n) for n in cfg.dropped_frames[camera])
    return entry if len(entry) > 1 else camera


def truth_volume(cfg: SimulationConfig, deformation: Deformation) -> pd.DataFrame:
    """Exact soil volume and strains at every frame."""
    frames = np.arange(cfg.frames)
    v0 = deformation.soil_volume(0.0)
    vol = np.array([deformation.soil_volume(progress(k, cfg.frames)) for k in frames])
    h = np.array([deformation.current_height(progress(k, cfg.frames)) for k in frames])
    return pd.DataFrame({
        "frame": frames.astype(np.int64),
        "time_s": frames / cfg.fps,
        "volume_mm3": vol,
        "axial_strain": (deformation.height - h) / deformation.height,
        "volumetric_strain": (v0 - vol) / v0,
    })  # fmt: skip


def target_positions(scene: Scene, frame: int) -> pd.DataFrame:
    """Cell-frame centre (x, y, z) of every target at a frame (membrane: printed surface)."""
    p = progress(frame, scene.cfg.frames)
    t = scene.table
    xyz = np.zeros((len(t), 3))
    for surface, sel in t.groupby("surface").groups.items():
        xyz[t.index.get_indexer(sel)] = _surface_points(
            scene, surface, t.loc[sel, ["theta_rad", "z_mm"]].to_numpy(), p
        )[0]
    return pd.DataFrame({"id": t["id"].to_numpy(), "x_mm": xyz[:, 0], "y_mm": xyz[:, 1], "z_mm": xyz[:, 2]})


def _surface_points(scene: Scene, surface: str, theta_z: np.ndarray, p: float):
    """3-D points and outward normals of (theta, z) surface coordinates at progress p."""
    th, z = theta_z[:, 0], theta_z[:, 1]
    if surface == "membrane":
        return scene.deformation.outer_surface(th, z, p)
    rad = surface_by_name(scene.design)[surface]["radius"]
    pts = np.c_[rad * np.cos(th), rad * np.sin(th), z]
    nrm = np.c_[np.cos(th), np.sin(th), np.zeros_like(th)]
    if surface == "pedestal_top":
        pts = pts + scene.deformation.top_displacement(p)
    return pts, nrm


# ---------------------------------------------------------------- rendering
def _strip_polygons(a: np.ndarray, b: np.ndarray, front: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outline polygons of the runs of front-facing quads in a closed strip.

    ``a`` and ``b`` are the (n + 1, 2) image points of the strip's two edges (the last equal to
    the first), ``front`` the (n,) facing of quad k between points k and k + 1. Each cyclic run
    of facing quads becomes one polygon; quads with non-finite corners end a run.
    """
    n = len(front)
    ok = (
        front
        & np.isfinite(a[:-1]).all(1)
        & np.isfinite(a[1:]).all(1)
        & np.isfinite(b[:-1]).all(1)
        & np.isfinite(b[1:]).all(1)
    )
    if not ok.any():
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    if ok.all():
        runs = [(0, n)]
    else:
        first_off = int(np.argmin(ok))
        order = [(first_off + k) % n for k in range(n)]
        runs, start = [], None
        for j, k in enumerate(order):
            if ok[k] and start is None:
                start = j
            if not ok[k] and start is not None:
                runs.append((order[start], j - start))
                start = None
        if start is not None:
            runs.append((order[start], n - start))
    verts, counts = [], []
    for k0, length in runs:
        idx = (k0 + np.arange(length + 1)) % n
        verts.append(np.vstack([a[idx], b[idx[::-1]]]))
        counts.append(2 * (length + 1))
    return np.vstack(verts), np.array(counts, np.int64)


class CameraRenderer:
    """Renders the frames of one camera in order, keeping last frame's ray solutions."""

    def __init__(self, scene: Scene, camera: str):
        self.scene = scene
        self.cam = scene.cameras[camera]
        self._xy: dict[str, np.ndarray] = {}
        self._xy_prev: dict[str, np.ndarray] = {}
        self._pinv: dict[str, np.ndarray] = {}
        h, w = self.cam.height, self.cam.width
        cfg = scene.cfg
        self._light = footage.vignetting_field(w, h, self.cam.K[0, 2], self.cam.K[1, 2], cfg.vignetting)
        if cfg.light_gradient > 0:
            direction = footage.gradient_direction(cfg.seed, camera)
            self._light = self._light * footage.gradient_field(w, h, cfg.light_gradient, direction)
        s = scene.deformation
        nt, nz = MEMBRANE_QUADS
        th, zz = np.meshgrid(2 * np.pi * np.arange(nt + 1) / nt, np.linspace(0, s.height, nz + 1))
        self._mgrid = np.c_[th.ravel(), zz.ravel()]
        self._mgrid_shape = (nz + 1, nt + 1)

    # -- projection with warm starts
    def _project(self, key: str, pts: np.ndarray, in_water: bool, sel: np.ndarray | None = None):
        """Pixels (N, 2) and water ray directions (N, 3) of points; ``sel`` picks which to solve."""
        n = len(pts)
        uv = np.full((n, 2), np.nan)
        d2 = np.full((n, 3), np.nan)
        sel = np.arange(n) if sel is None else np.flatnonzero(sel)
        if not in_water:
            uv[sel] = project_air(self.cam, pts[sel])
            return uv, d2
        cache = self._xy.get(key)
        if cache is None or len(cache) != n:
            cache = np.full((n, 2), np.nan)
        prev = self._xy_prev.get(key)
        xy0 = cache[sel]
        if prev is not None and len(prev) == n:  # frames are rendered in order: extrapolate
            lin = 2 * cache[sel] - prev[sel]
            xy0 = np.where(np.isfinite(lin), lin, xy0)
        pinv = self._pinv.get(key)
        pinv = np.full((n, 2, 3), np.nan) if pinv is None or len(pinv) != n else pinv
        uv[sel], d2[sel], sol = project_water(self.cam, pts[sel], self.scene.cell, xy0, pinv[sel])
        self._xy_prev[key] = cache
        cache = cache.copy()
        cache[sel] = sol.xy
        self._xy[key] = cache
        pinv = pinv.copy()
        pinv[sel] = sol.pinv
        self._pinv[key] = pinv
        return uv, d2

    def _facing(self, pts, nrm, d2, in_water):
        """Cosine between the outward normal and the direction back towards the camera."""
        if in_water:
            return -np.einsum("ij,ij->i", nrm, d2)
        v = self.cam.center - pts
        return np.einsum("ij,ij->i", nrm, v) / np.linalg.norm(v, axis=1)

    def _shape_layer(self, shapes: ShapeSet, p: float):
        """Projected polygons of a shape set, culled; plus the per-polygon centre data."""
        sc = self.scene
        in_water = surface_by_name(sc.design)[shapes.surface]["medium_outside"] == "water"
        cpts, cnrm = _surface_points(sc, shapes.surface, shapes.center, p)
        cuv, cd2 = self._project(f"{shapes.surface}/{shapes.layer}/c", cpts, in_water)
        cos = self._facing(cpts, cnrm, cd2, in_water)
        keep = cos > 0
        vsel = np.repeat(keep, shapes.counts)
        vpts = np.full((len(shapes.theta_z), 3), np.nan)
        vpts[vsel] = _surface_points(sc, shapes.surface, shapes.theta_z[vsel], p)[0]
        vuv, _ = self._project(f"{shapes.surface}/{shapes.layer}/v", vpts, in_water, vsel)
        return vuv[vsel], shapes.counts[keep], keep, cuv, cos

    def _base_layers(self, p: float) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Untextured surfaces as strips of front-facing quads: pedestal sides and visible end
        faces, then the membrane (their outlines only; the printed shapes are drawn exactly)."""
        sc = self.scene
        out = []
        ped = sc.design["pedestal"]
        h0 = sc.design["specimen"]["height"]
        n = PEDESTAL_QUADS
        t = 2 * np.pi * np.arange(n + 1) / n
        r_m = sc.deformation.radius + sc.deformation.membrane_thickness
        for name, z0, z1, face_z, face_sign in (
            ("pedestal_bottom", -ped["height"], 0.0, 0.0, 1.0),
            ("pedestal_top", h0, h0 + ped["height"], h0, -1.0),
        ):
            shift = sc.deformation.top_displacement(p) if name == "pedestal_top" else np.zeros(3)
            rad = ped["radius"]

            def ring(r, z, shift=shift):
                return np.c_[r * np.cos(t), r * np.sin(t), np.full_like(t, z)] + shift

            side_n = np.c_[np.cos(t), np.sin(t), 0 * t]
            face_n = np.c_[0 * t, 0 * t, face_sign + 0 * t]
            for (ra, za), (rb, zb), nrm, grey, kind in (
                ((rad, z0), (rad, z1), side_n, GREY_PEDESTAL_SIDE, "side"),
                ((r_m, face_z), (rad, face_z), face_n, GREY_PEDESTAL_FACE, "face"),
            ):
                pts = np.vstack([ring(ra, za), ring(rb, zb)])
                uv, d2 = self._project(f"{name}/{kind}", pts, True)
                cos = -((nrm[:n] + nrm[1:]) * (d2[:n] + d2[1 : n + 1])).sum(axis=1)
                verts, counts = _strip_polygons(uv[: n + 1], uv[n + 1 :], cos > 0)
                out.append((verts, counts, grey))
        # membrane: one strip per row of quads
        pts, nrm = sc.deformation.outer_surface(self._mgrid[:, 0], self._mgrid[:, 1], p)
        c = self.cam.center
        rough = np.einsum("ij,ij->i", nrm, c - pts) > -0.5 * np.linalg.norm(c - pts, axis=1)
        uv, d2 = self._project("membrane/grid", pts, True, rough)
        nz, nt = self._mgrid_shape
        uv = uv.reshape(nz, nt, 2)
        cos = (-np.einsum("ij,ij->i", nrm, d2)).reshape(nz, nt)
        qcos = cos[:-1, :-1] + cos[:-1, 1:] + cos[1:, 1:] + cos[1:, :-1]
        vs, cs = [], []
        for i in range(nz - 1):
            v, cnt = _strip_polygons(uv[i], uv[i + 1], qcos[i] > 0)
            vs.append(v)
            cs.append(cnt)
        out.append((np.vstack(vs), np.concatenate(cs), GREY_MEMBRANE))
        return out

    def _occluder_polygons(self, p: float) -> tuple[np.ndarray, np.ndarray]:
        """Image polygons (packed vertices, counts) of the front-facing membrane surface
        between cell-frame heights ``occluder_z_mm`` at progress p (the occluder band).

        The band's edges are the printed surface's points at those heights (z in the cell frame,
        so the material slides under a fixed band as the specimen compresses), clipped to the
        membrane (0 .. the current height); empty if the band misses the membrane.
        """
        sc = self.scene
        s = sc.deformation
        z0, z1 = np.clip(np.asarray(sc.cfg.occluder_z_mm, float), 0.0, s.current_height(p))
        if z1 <= z0:
            return np.zeros((0, 2)), np.zeros(0, np.int64)
        nt = OCCLUDER_QUADS
        nz = int(np.ceil((z1 - z0) / OCCLUDER_ROW_MM))
        th = 2 * np.pi * np.arange(nt + 1) / nt
        T, ZC = np.meshgrid(th, np.linspace(z0, z1, nz + 1))
        Z = material_height(s, ZC.ravel(), T.ravel(), p)
        pts, nrm = s.outer_surface(T.ravel(), Z, p)
        c = self.cam.center
        rough = np.einsum("ij,ij->i", nrm, c - pts) > -0.5 * np.linalg.norm(c - pts, axis=1)
        uv, d2 = self._project("occluder", pts, True, rough)
        uv = uv.reshape(nz + 1, nt + 1, 2)
        cos = (-np.einsum("ij,ij->i", nrm, d2)).reshape(nz + 1, nt + 1)
        qcos = cos[:-1, :-1] + cos[:-1, 1:] + cos[1:, 1:] + cos[1:, :-1]
        vs, cs = [], []
        for i in range(nz):
            v, cnt = _strip_polygons(uv[i], uv[i + 1], qcos[i] > 0)
            vs.append(v)
            cs.append(cnt)
        return np.vstack(vs), np.concatenate(cs)

    def render(self, frame: int) -> tuple[np.ndarray, pd.DataFrame]:
        """The camera's uint8 grey image at ``frame`` and the exact observations it holds."""
        sc, cam = self.scene, self.cam
        p = progress(frame, sc.cfg.frames)
        h, w = cam.height, cam.width
        img = np.full((h, w), GREY_BACKGROUND)
        layers = self._base_layers(p)
        for verts, counts, grey in layers[:4]:  # pedestals
            paint_into(img, verts, counts, grey, SUBROWS_PLAIN)
        obs = []
        band_cov = None
        occluder_cov = None
        order: list = [s for s in sc.shapes if s.surface.startswith("pedestal")]
        order += [None]  # the membrane outline goes here
        order += [s for s in sc.shapes if s.surface == "membrane"]
        order += ["occluder"] if sc.cfg.occluder_z_mm is not None else []
        order += [s for s in sc.shapes if s.surface == "cell_outer"]
        pending = []
        for shapes in order:
            if shapes is None:
                verts, counts, grey = layers[4]
                paint_into(img, verts, counts, grey, SUBROWS_PLAIN)
                continue
            if isinstance(shapes, str):  # the occluder band, over the membrane and its dots
                verts, counts = self._occluder_polygons(p)
                r0, cov = paint_into(img, verts, counts, GREY_OCCLUDER, SUBROWS_PLAIN)
                occluder_cov = np.zeros((h, w))
                occluder_cov[r0 : r0 + len(cov)] = cov
                continue
            vuv, counts, keep, cuv, cos = self._shape_layer(shapes, p)
            ink = shapes.layer == "ink"
            grey = GREY_INK if ink else GREY_LABEL
            r0, cov = paint_into(img, vuv, counts, grey, SUBROWS_INK if ink else SUBROWS_PLAIN)
            if shapes.surface == "cell_outer" and shapes.layer == "label":
                band_cov = np.zeros((h, w)) if band_cov is None else band_cov
                np.maximum(band_cov[r0 : r0 + len(cov)], cov, out=band_cov[r0 : r0 + len(cov)])
            if shapes.layer == "ink":
                pending.append((shapes, vuv, counts, keep, cuv, cos))
        for shapes, vuv, counts, keep, cuv, cos in pending:
            obs.append(self._observations(shapes, vuv, counts, keep, cuv, cos, band_cov, occluder_cov, frame))
        img = self._camera_effects(img, frame)
        return img, pd.concat(obs, ignore_index=True)

    def _observations(
        self, shapes, vuv, counts, keep, cuv, cos, band_cov, occluder_cov, frame
    ) -> pd.DataFrame:
        """The targets a user could see in this image: the truth observations.

        A target is seen when its whole image is ``EDGE_MARGIN_PX`` inside the frame, it faces
        the camera (``min_view_cos``), and nothing hides any of it: a white band of the cell
        wall (``band_cov``: coverage above ``OCCLUSION_TOL`` anywhere in the target's image box),
        the occluder band (``occluder_cov``, same rule; targets of the cell wall are in front of
        it) or the timestamp overlay (``footage.overlay_box``: the target's image box comes within
        ``EDGE_MARGIN_PX`` of it). ``triaxtrack score`` counts coverage as labelled / seen here.
        """
        cam = self.cam
        ids_kept = shapes.ids[keep]
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        lo = np.minimum.reduceat(vuv, starts) if len(counts) else np.zeros((0, 2))
        hi = np.maximum.reduceat(vuv, starts) if len(counts) else np.zeros((0, 2))
        # a target may have several ink polygons (a CT): combine by ID
        df = pd.DataFrame({"id": ids_kept, "u0": lo[:, 0], "v0": lo[:, 1], "u1": hi[:, 0], "v1": hi[:, 1]})
        box = df.groupby("id").agg(u0=("u0", "min"), v0=("v0", "min"), u1=("u1", "max"), v1=("v1", "max"))
        m = EDGE_MARGIN_PX
        inside = (
            (box.u0 >= m) & (box.v0 >= m) & (box.u1 <= cam.width - 1 - m) & (box.v1 <= cam.height - 1 - m)
        )
        box = box[inside & np.isfinite(box).all(axis=1)]
        centre = pd.DataFrame({"id": shapes.ids, "u_px": cuv[:, 0], "v_px": cuv[:, 1], "cos": cos})
        centre = centre.drop_duplicates("id").set_index("id").loc[box.index]
        centre = centre[centre.cos >= self.scene.cfg.min_view_cos]
        for cov in (band_cov, occluder_cov):
            if shapes.surface != "cell_outer" and cov is not None and len(centre):
                centre = centre[~_covered(cov, box.loc[centre.index])]
        if self.scene.cfg.timestamp_overlay and len(centre):
            b = box.loc[centre.index, ["u0", "v0", "u1", "v1"]].to_numpy()
            centre = centre[~footage.boxes_overlap(b, footage.overlay_box(cam.width, cam.height), m)]
        return pd.DataFrame({
            "camera": cam.name,
            "frame": np.int64(frame),
            "id": centre.index.to_numpy(np.int64),
            "u_px": centre.u_px.to_numpy(),
            "v_px": centre.v_px.to_numpy(),
        })  # fmt: skip

    def _camera_effects(self, img: np.ndarray, frame: int) -> np.ndarray:
        """Camera and recorder effects, in the order they happen (:mod:`triaxtrack.footage`):
        light (vignetting, light gradient, exposure drift), optional blur, the timestamp
        overlay, sensor noise (seeded per camera and frame), rounding to 8 bits."""
        cfg, cam = self.scene.cfg, self.cam
        img = img * self._light
        if cfg.exposure_drift > 0:
            gain = footage.exposure_gain(progress(frame, cfg.frames), cfg.exposure_drift, cfg.seed, cam.name)
            img = img * gain
        if cfg.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma_px)
        if cfg.timestamp_overlay:
            img = footage.draw_timestamp(img, footage.timestamp_text(frame, cfg.fps))
        rng = footage.camera_rng(cfg.seed, cam.name, (frame,))
        noise = rng.standard_normal(img.shape, dtype=np.float32)
        img = img + cfg.noise_sigma * noise * np.sqrt(np.maximum(img, 1) / 128)  # shot-noise-like
        return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _covered(cov: np.ndarray, boxes: pd.DataFrame) -> np.ndarray:
    """Per image box (rows with ``u0, v0, u1, v1``, pixels): is the (h, w) coverage ``cov``
    above ``OCCLUSION_TOL`` anywhere in the pixels the box touches?"""
    hit = [
        cov[int(np.floor(r.v0)) : int(np.ceil(r.v1)) + 1, int(np.floor(r.u0)) : int(np.ceil(r.u1)) + 1].max()
        > OCCLUSION_TOL
        for r in boxes.itertuples()
    ]
    return np.array(hit, bool)


def material_height(deformation: Deformation, z: np.ndarray, theta: np.ndarray, p: float) -> np.ndarray:
    """Material height Z (mm) of the printed membrane surface's points at cell-frame height
    ``z`` (mm) and azimuth ``theta`` (rad), progress p.

    The soil surface's height ``z = H g(Z / H0)``, ``g(zeta) = zeta - k zeta (1 - zeta)``, is
    inverted exactly; ``OCCLUDER_NEWTON_STEPS`` fixed-point steps then move to the printed
    surface (offset along the normal by the membrane thickness: under 0.02 mm in z).
    """
    s = deformation
    k = s.axial_nonuniformity * p
    hc = s.current_height(p)
    z = np.asarray(z, float)
    theta = np.asarray(theta, float)

    def soil_inverse(zz: np.ndarray) -> np.ndarray:
        u = np.clip(zz / hc, 0.0, 1.0)
        return s.height * 2 * u / ((1 - k) + np.sqrt((1 - k) ** 2 + 4 * k * u))  # stable root

    Z = soil_inverse(z)
    for _ in range(OCCLUDER_NEWTON_STEPS):
        dz = s.outer_surface(theta, Z, p)[0][:, 2] - s.inner_surface(theta, Z, p)[:, 2]
        Z = soil_inverse(z - dz)
    return Z


def render_chunk(
    test_dir: str | Path,
    camera: str,
    start: int,
    stop: int,
    video_out: str | Path,
    observations_out: str | Path,
) -> None:
    """Render test frames ``[start, stop)`` of one camera: an H.264/H.265 segment of the frames
    the camera recorded (:func:`recorded_frames`) and their truth observations (by test frame).

    Every frame of the range is rendered, recorded or not, so the recorded ones are the very
    images of a camera without offset or drops. ValueError if the camera recorded none of them
    (the segment would be empty: use a larger chunk_size or a smaller offset).
    """
    scene = load_scene(test_dir)
    rend = CameraRenderer(scene, camera)
    cam = scene.cameras[camera]
    recorded = set(recorded_frames(scene.cfg, camera).tolist())
    if not recorded & set(range(start, stop)):
        raise ValueError(
            f"{camera} recorded none of test frames {start}..{stop - 1} (start_offset_s, dropped_frames): "
            "a video segment cannot be empty; use a larger chunk_size"
        )
    obs = []
    Path(video_out).parent.mkdir(parents=True, exist_ok=True)
    with VideoWriter(
        video_out, cam.width, cam.height, scene.cfg.fps, codec=scene.cfg.codec, crf=scene.cfg.crf
    ) as vw:
        for k in range(start, stop):
            img, o = rend.render(k)
            if k in recorded:
                vw.write(img)
                obs.append(o)
    write_table(pd.concat(obs, ignore_index=True), observations_out, OBSERVATIONS)


# ---------------------------------------------------------------- calibration images
def corner_board_count(n: int) -> int:
    """How many of ``n`` calibration images show a board across an image corner
    (``BOARD_CORNER_SHARE`` of them, a multiple of 4; none below 10 images)."""
    return 4 * int(BOARD_CORNER_SHARE * n / 4 + 0.5) if n >= 10 else 0


def _tilted_rotation(rng: np.random.Generator) -> np.ndarray:
    """A board rotation (board -> camera): tilt ``BOARD_TILT_DEG`` about a random in-plane axis
    after a roll of up to ``BOARD_ROLL_DEG``."""
    azimuth = rng.uniform(0, 2 * np.pi)
    tilt = np.deg2rad(rng.uniform(*BOARD_TILT_DEG))
    roll = np.deg2rad(rng.uniform(-1, 1) * BOARD_ROLL_DEG)
    return (
        cv2.Rodrigues(tilt * np.r_[np.cos(azimuth), np.sin(azimuth), 0])[0]
        @ cv2.Rodrigues(np.r_[0, 0, roll])[0]
    )


def _within_view_angle(R: np.ndarray, t: np.ndarray, centre: np.ndarray) -> bool:
    """True when the board's normal is within ``BOARD_MAX_VIEW_DEG`` of the line of sight to
    ``centre`` (a board point, mm)."""
    to_board = R @ centre + t
    cos_view = abs(R[:, 2] @ to_board) / np.linalg.norm(to_board)
    return bool(cos_view >= np.cos(np.deg2rad(BOARD_MAX_VIEW_DEG)))


def _whole_board_pose(
    rng: np.random.Generator, camera: Camera, sheet_mm: np.ndarray, anchor: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray] | None:
    """One tilted pose of the whole sheet (corners ``sheet_mm``, (M, 3)) pushed to the image
    edges of ``anchor``; None if it does not fit in the image."""
    w, h = camera.width, camera.height
    ax, ay = anchor
    lo_mm, hi_mm = sheet_mm.min(axis=0), sheet_mm.max(axis=0)
    centre = (lo_mm + hi_mm) / 2
    dist = rng.uniform(*BOARD_DISTANCE_MM)
    R = _tilted_rotation(rng)
    t = np.r_[0.0, 0.0, dist] - R @ centre

    def image_of(t: np.ndarray) -> np.ndarray:
        return project_air(Camera("b", w, h, camera.K, camera.dist, R, t), sheet_mm)

    for _ in range(BOARD_SHIFT_STEPS):
        uv = image_of(t)
        if not np.isfinite(uv).all():
            break
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        jitter = rng.uniform(0, 3, 2)
        du = (
            BOARD_EDGE_PX + jitter[0] - lo[0],
            (w - 1 - lo[0] - hi[0]) / 2,
            w - 1 - BOARD_EDGE_PX - jitter[0] - hi[0],
        )[ax + 1]
        dv = (
            BOARD_EDGE_PX + jitter[1] - lo[1],
            (h - 1 - lo[1] - hi[1]) / 2,
            h - 1 - BOARD_EDGE_PX - jitter[1] - hi[1],
        )[ay + 1]
        # pixels to mm at the board centre's depth; 0.9 damps the step (distortion)
        t = t + 0.9 * np.r_[du, dv, 0.0] * dist / camera.K[0, 0]
    uv = image_of(t)
    pc = sheet_mm @ R.T + t
    if (
        (pc[:, 2] > 50).all()
        and _within_view_angle(R, t, centre)
        and np.isfinite(uv).all()
        and (uv >= 10).all()
        and (uv[:, 0] <= w - 11).all()
        and (uv[:, 1] <= h - 11).all()
    ):
        return R, t
    return None


def _corner_board_pose(
    rng: np.random.Generator,
    camera: Camera,
    corners_mm: np.ndarray,
    sheet_mm: np.ndarray,
    corner: tuple[int, int],
) -> tuple[np.ndarray, np.ndarray] | None:
    """One tilted pose of a board running off the image across image ``corner`` ((-1 | 1,
    -1 | 1): left | right, top | bottom): a random inner corner (``corners_mm``, (N, 3)) lands
    ``BOARD_CORNER_INSET_PX`` from both edges there; None if too few corners are seen."""
    w, h = camera.width, camera.height
    target = np.r_[
        (BOARD_CORNER_INSET_PX, w - 1 - BOARD_CORNER_INSET_PX)[(corner[0] + 1) // 2],
        (BOARD_CORNER_INSET_PX, h - 1 - BOARD_CORNER_INSET_PX)[(corner[1] + 1) // 2],
    ]
    anchor = corners_mm[rng.integers(len(corners_mm))]
    R = _tilted_rotation(rng)
    t = np.r_[0.0, 0.0, rng.uniform(*BOARD_CORNER_DISTANCE_MM)] - R @ anchor

    def image_of(t: np.ndarray, pts: np.ndarray) -> np.ndarray:
        return project_air(Camera("b", w, h, camera.K, camera.dist, R, t), pts)

    for _ in range(BOARD_SHIFT_STEPS):  # Newton steps on the board's sideways shift (mm)
        uv = image_of(t, anchor[None])[0]
        shifted = (
            image_of(t + np.r_[1.0, 0, 0], anchor[None])[0],
            image_of(t + np.r_[0, 1.0, 0], anchor[None])[0],
        )
        J = np.c_[shifted[0] - uv, shifted[1] - uv]  # pixels per mm of shift
        if not (np.isfinite(J).all() and np.isfinite(uv).all()) or abs(np.linalg.det(J)) < 1e-9:
            return None
        t = t + np.r_[np.linalg.solve(J, target - uv), 0.0]
    uv = image_of(t, corners_mm)
    seen = (
        np.isfinite(uv).all(axis=1)
        & (uv >= BOARD_CORNER_SEEN_PX).all(axis=1)
        & (uv[:, 0] <= w - 1 - BOARD_CORNER_SEEN_PX)
        & (uv[:, 1] <= h - 1 - BOARD_CORNER_SEEN_PX)
    )
    near = np.hypot(*(image_of(t, anchor[None])[0] - target)) < 1.0
    lines = min(len(np.unique(corners_mm[seen, 0])), len(np.unique(corners_mm[seen, 1])))
    if (
        near
        and seen.sum() >= BOARD_CORNER_MIN_SEEN
        and lines >= BOARD_CORNER_MIN_LINES
        and ((sheet_mm @ R.T + t)[:, 2] > 50).all()
        and _within_view_angle(R, t, anchor)
    ):
        return R, t
    return None


def board_poses(
    cfg: SimulationConfig, camera: Camera, board: dict, n: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Seeded board poses (R, t board -> camera, mm) of a careful calibration session for a
    wide-angle camera: ``n - corner_board_count(n)`` whole boards, strongly tilted and pushed
    into every part of the image in turn (``BOARD_ANCHORS``), then boards running off the image
    across each image corner in turn (``BOARD_CORNER_ORDER``).

    Every pose is tilted by ``BOARD_TILT_DEG`` about an in-plane axis of random direction and
    rolled by up to ``BOARD_ROLL_DEG``. A whole board is then shifted until its image touches
    the image edges on its anchor's sides (``BOARD_EDGE_PX``); its whole sheet stays inside the
    image. A corner board is shifted until one of its inner corners, picked at random, lies
    ``BOARD_CORNER_INSET_PX`` from both edges at the image corner; the rest of the board runs
    off the image there, so corners are measured where the distortion is strongest.
    """
    rng = footage.camera_rng(cfg.seed, camera.name, (7,))
    sheet, _ = board_polygons_mm(board)
    sheet_mm = np.c_[sheet, np.zeros(len(sheet))]
    corners_mm = board_corners_mm(board)
    n_corner = corner_board_count(n)
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(poses) < n and tries < BOARD_MAX_TRIES:
        tries += 1
        k = len(poses)
        if k < n - n_corner:
            pose = _whole_board_pose(rng, camera, sheet_mm, BOARD_ANCHORS[k % len(BOARD_ANCHORS)])
        else:
            corner = BOARD_CORNER_ORDER[(k - n + n_corner) % len(BOARD_CORNER_ORDER)]
            pose = _corner_board_pose(rng, camera, corners_mm, sheet_mm, corner)
        if pose is not None:
            poses.append(pose)
    if len(poses) < n:
        raise RuntimeError(f"could not place {n} calibration boards for {camera.name}")
    return poses


def render_board_image(
    camera: Camera, board: dict, R: np.ndarray, t: np.ndarray, noise: float, rng
) -> np.ndarray:
    """uint8 image of the checkerboard at pose (R, t) seen by ``camera`` (exact, distorted)."""
    bcam = Camera("b", camera.width, camera.height, camera.K, camera.dist, R, t)
    sheet, squares = board_polygons_mm(board, subdivide=8)
    h, w = camera.height, camera.width
    img = np.full((h, w), GREY_BACKGROUND)

    def project(poly):
        return project_air(bcam, np.c_[poly, np.zeros(len(poly))])

    paint_into(img, project(sheet), [len(sheet)], GREY_LABEL)
    sq = np.vstack(squares)
    paint_into(img, project(sq), [len(s) for s in squares], GREY_INK)
    img = img + rng.normal(0, noise, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_calibration(test_dir: str | Path, camera: str, out_dir: str | Path) -> None:
    """Calibration board images of one camera (PNG) and, in truth/, the board poses.

    ``truth/calibration/<camera>.json``: ``{"board_poses": [{"image", "kind", "R", "t",
    "corners_px"}, ...]}``, one per image in order: ``kind`` is ``whole`` or ``corner``
    (:func:`board_poses`), R and t take board millimetres (:func:`triaxtrack.kit.board_corners_mm`
    frame) to the camera frame, and ``corners_px`` is the exact distorted image of every inner
    corner, in the order of ``board_corners_mm``: for a ``corner`` board some lie outside the
    image.
    """
    test_dir, out_dir = Path(test_dir), Path(out_dir)
    scene = load_scene(test_dir)
    cam = scene.cameras[camera]
    board = scene.design["board"]
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = footage.camera_rng(scene.cfg.seed, camera, (11,))
    n = scene.cfg.calibration_images
    poses = board_poses(scene.cfg, cam, board, n)
    n_whole = n - corner_board_count(n)
    record = []
    for i, (R, t) in enumerate(poses):
        img = render_board_image(cam, board, R, t, scene.cfg.noise_sigma, rng)
        cv2.imwrite(str(out_dir / f"{i + 1:02d}.png"), img)
        uv = project_air(Camera("b", cam.width, cam.height, cam.K, cam.dist, R, t), board_corners_mm(board))
        record.append({
            "image": f"{i + 1:02d}.png",
            "kind": "whole" if i < n_whole else "corner",
            "R": R.tolist(),
            "t": t.tolist(),
            "corners_px": uv.tolist(),
        })  # fmt: skip
    truth = test_dir / "truth" / "calibration"
    truth.mkdir(parents=True, exist_ok=True)
    (truth / f"{camera}.json").write_text(json.dumps({"board_poses": record}))


# ---------------------------------------------------------------- truth tables
def finish_truth(test_dir: str | Path, observation_parts: list[str | Path]) -> None:
    """Gather the per-chunk observations into ``truth/observations.parquet`` and write
    ``truth/points.parquet`` (every target at every frame, ``n_rays`` = cameras that see it)."""
    test_dir = Path(test_dir)
    scene = load_scene(test_dir)
    obs = pd.concat([read_table(p, OBSERVATIONS) for p in observation_parts], ignore_index=True)
    write_table(obs, test_dir / "truth" / "observations.parquet", OBSERVATIONS)
    n_rays = obs.groupby(["frame", "id"]).size()
    rows = []
    for k in range(scene.cfg.frames):
        pos = target_positions(scene, k)
        pos.insert(0, "frame", np.int64(k))
        pos.insert(1, "time_s", k / scene.cfg.fps)
        rows.append(pos)
    pts = pd.concat(rows, ignore_index=True)
    key = pd.MultiIndex.from_arrays([pts.frame, pts.id])
    pts["n_rays"] = n_rays.reindex(key).fillna(0).astype(np.int64).to_numpy()
    pts["rms_px"] = 0.0
    write_table(pts, test_dir / "truth" / "points.parquet", POINTS)


def simulate_test(
    cfg: SimulationConfig, kit_dir: str | Path, test_dir: str | Path, name: str, chunk_size: int = 50
) -> None:
    """The whole simulation in one process (what the workflow fans out per camera and chunk)."""
    from triaxtrack.video import concat_videos

    test_dir = Path(test_dir)
    make_scene(cfg, kit_dir, test_dir, name)
    work = test_dir / ".chunks"
    parts = []
    for cam in camera_names(cfg.cameras):
        segs = []
        for start in range(0, cfg.frames, chunk_size):
            stop = min(start + chunk_size, cfg.frames)
            seg = work / cam / f"{start:06d}.mp4"
            obs = work / cam / f"{start:06d}.parquet"
            render_chunk(test_dir, cam, start, stop, seg, obs)
            segs.append(seg)
            parts.append(obs)
        (test_dir / "videos").mkdir(exist_ok=True)
        concat_videos(segs, test_dir / "videos" / f"{cam}.mp4")
        render_calibration(test_dir, cam, test_dir / "calibration" / cam)
    finish_truth(test_dir, parts)
    shutil.rmtree(work)


# ---------------------------------------------------------------- self-check
def centroid_errors(
    observations: pd.DataFrame, targets: pd.DataFrame, gray: np.ndarray, sample: int | None = None
) -> pd.DataFrame:
    """Rendered centroid minus exact image of the centre, for dots seen in one image.

    ``observations``: truth rows of one camera and frame; ``targets``: the kit's targets.csv
    indexed by ``id``; ``gray``: the decoded image. ``sample``: measure at most this many dots
    per surface (a seeded choice); all by default. Columns: ``id``, ``surface``, ``du_px``,
    ``dv_px``, ``err_px`` (NaN where the blob is not isolated in its window).
    """
    obs = observations[targets.loc[observations.id, "kind"].to_numpy() == "dot"]
    surface = targets.loc[obs.id, "surface"].to_numpy()
    if sample is not None:
        rng = np.random.default_rng(0)
        keep = np.zeros(len(obs), bool)
        for name in np.unique(surface):
            idx = np.flatnonzero(surface == name)
            keep[rng.choice(idx, size=min(sample, len(idx)), replace=False)] = True
        obs, surface = obs[keep], surface[keep]
    uv = obs[["u_px", "v_px"]].to_numpy()
    d = local_centroid(gray, uv) - uv
    return pd.DataFrame({
        "id": obs.id.to_numpy(),
        "surface": surface,
        "du_px": d[:, 0],
        "dv_px": d[:, 1],
        "err_px": np.hypot(d[:, 0], d[:, 1]),
    })  # fmt: skip


def check_simulation(test_dir: str | Path, out_json: str | Path | None = None) -> dict:
    """Measure a simulated test against its own truth; optionally write the figures as JSON.

    For the first and last test frame every camera recorded, decoded from its video through the
    frame map (:mod:`triaxtrack.frames`, so start offsets and dropped frames are honoured): the
    contrast-weighted centroid of the dots the truth says the camera sees (a seeded sample of
    ``CHECK_SAMPLE`` per surface), against the exact image of the dot's centre. Cell-wall dots
    are seen in air; membrane dots through both walls and the water. Also checks frame counts
    and calibration images. ``ok`` is true when every video has the frames its camera recorded
    and the median errors are within 0.10 px (air) and 0.15 px (water).
    """
    from triaxtrack.frames import frame_map, read_camera_timing, read_test_frame
    from triaxtrack.video import probe_video

    test_dir = Path(test_dir)
    scene_cfg = SimulationConfig.from_dict(
        json.loads((test_dir / "truth" / "scene.json").read_text())["simulation"]
    )
    meta = yaml.safe_load((test_dir / "test.yaml").read_text())
    truth_obs = read_table(test_dir / "truth" / "observations.parquet", OBSERVATIONS)
    targets = pd.read_csv(test_dir / "kit" / "targets.csv").set_index("id")
    rows, per_camera = [], {}
    for entry in meta["cameras"]:
        cam = entry["name"] if isinstance(entry, dict) else entry
        video = test_dir / "videos" / f"{cam}.mp4"
        info = probe_video(video)
        n_cal = len(list((test_dir / "calibration" / cam).glob("*.png")))
        recorded = recorded_frames(scene_cfg, cam)
        fmap = frame_map(read_camera_timing(test_dir / "test.yaml", cam), scene_cfg.frames, info["frames"])
        for frame in sorted({int(recorded[0]), int(recorded[-1])}):
            image = read_test_frame(video, fmap, frame)
            if image is None:
                continue  # the video is short: counted below
            sel = truth_obs[(truth_obs.camera == cam) & (truth_obs.frame == frame)]
            e = centroid_errors(sel, targets, image, CHECK_SAMPLE)
            e["camera"], e["frame"] = cam, frame
            rows.append(e)
        per_camera[cam] = {
            "frames": info["frames"],
            "frames_expected": len(recorded),
            "calibration_images": n_cal,
        }
    err = pd.concat(rows, ignore_index=True)

    def stats(sel: pd.DataFrame) -> dict:
        ok = sel.dropna()
        return {
            "n": int(len(ok)),
            "measured_fraction": float(len(ok) / max(len(sel), 1)),
            "median_px": float(ok.err_px.median()) if len(ok) else None,
            "p95_px": float(ok.err_px.quantile(0.95)) if len(ok) else None,
            "bias_u_px": float(ok.du_px.mean()) if len(ok) else None,
            "bias_v_px": float(ok.dv_px.mean()) if len(ok) else None,
        }

    air = stats(err[err.surface == "cell_outer"])
    water = stats(err[err.surface == "membrane"])
    for cam in per_camera:
        sel = err[err.camera == cam]
        per_camera[cam]["air_median_px"] = stats(sel[sel.surface == "cell_outer"])["median_px"]
        per_camera[cam]["water_median_px"] = stats(sel[sel.surface == "membrane"])["median_px"]
    frames_ok = all(c["frames"] == c["frames_expected"] for c in per_camera.values())
    ok = bool(frames_ok and air["median_px"] is not None and air["median_px"] <= 0.10
              and water["median_px"] is not None and water["median_px"] <= 0.15)  # fmt: skip
    report = {"test": meta["name"], "ok": ok, "frames_expected": scene_cfg.frames, "air_dots": air,
              "membrane_dots": water, "cameras": per_camera}  # fmt: skip
    if out_json is not None:
        Path(out_json).write_text(json.dumps(report, indent=2))
    return report
