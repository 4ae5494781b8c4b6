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

Modules:

* :mod:`~triaxtrack.simulate.config`: :class:`SimulationConfig`, ``PRESETS``, the frames each
  camera records (:func:`recorded_frames`) and the video segments rendered on the recorder's
  GOP grid (:func:`gop_frames`, :func:`render_segments`);
* :mod:`~triaxtrack.simulate.cameras`: the seeded ring of cameras (:func:`make_cameras`);
* :mod:`~triaxtrack.simulate.scene`: :class:`Scene` (:func:`load_scene`) and the surfaces' points
  at a loading progress;
* :mod:`~triaxtrack.simulate.render`: :class:`CameraRenderer`, what is drawn and the truth
  observations;
* :mod:`~triaxtrack.simulate.boards`: the calibration boards' poses and images
  (:func:`board_poses`, :func:`render_calibration`);
* :mod:`~triaxtrack.simulate.truth`: the truth tables (:func:`truth_volume`,
  :func:`target_positions`, :func:`finish_truth`);
* :mod:`~triaxtrack.simulate.folder`: the test folder (:func:`make_scene`, :func:`render_chunk`,
  :func:`simulate_test`);
* :mod:`~triaxtrack.simulate.check`: the simulator's self-check (:func:`check_simulation`).
"""

from triaxtrack.simulate.boards import (
    BOARD_ANCHORS,
    BOARD_CORNER_DISTANCE_MM,
    BOARD_CORNER_INSET_PX,
    BOARD_CORNER_MIN_LINES,
    BOARD_CORNER_MIN_SEEN,
    BOARD_CORNER_ORDER,
    BOARD_CORNER_SEEN_PX,
    BOARD_CORNER_SHARE,
    BOARD_DISTANCE_MM,
    BOARD_EDGE_PX,
    BOARD_MAX_TRIES,
    BOARD_MAX_VIEW_DEG,
    BOARD_ROLL_DEG,
    BOARD_SHIFT_STEPS,
    BOARD_TILT_DEG,
    board_poses,
    corner_board_count,
    render_board_image,
    render_calibration,
)
from triaxtrack.simulate.cameras import (
    JITTER_ANGLE_DEG,
    JITTER_FOCAL_REL,
    JITTER_K1,
    JITTER_K2,
    JITTER_P,
    JITTER_POSITION_MM,
    JITTER_PRINCIPAL_REL,
    JITTER_ROTATION_DEG,
    TILT_STREAM,
    camera_pitch_deg,
    look_at,
    make_cameras,
    tilt_rotation,
)
from triaxtrack.simulate.check import CHECK_SAMPLE, centroid_errors, check_simulation
from triaxtrack.simulate.config import (
    MAX_TILT_DEG,
    NVR_LENS_BLUR_PX,
    PRESETS,
    VIGNETTING,
    SimulationConfig,
    apply_preset,
    camera_names,
    check_loading_history,
    gop_frames,
    loading_progress,
    recorded_frames,
    render_segments,
)
from triaxtrack.simulate.folder import make_scene, render_chunk, simulate_test
from triaxtrack.simulate.render import (
    EDGE_MARGIN_PX,
    GREY_BACKGROUND,
    GREY_INK,
    GREY_LABEL,
    GREY_MEMBRANE,
    GREY_OCCLUDER,
    GREY_PEDESTAL_FACE,
    GREY_PEDESTAL_SIDE,
    MEMBRANE_QUADS,
    OCCLUDER_QUADS,
    OCCLUDER_ROW_MM,
    OCCLUSION_TOL,
    PEDESTAL_QUADS,
    SUBROWS_INK,
    SUBROWS_PLAIN,
    CameraRenderer,
)
from triaxtrack.simulate.scene import (
    OCCLUDER_NEWTON_STEPS,
    Scene,
    deformation_for,
    frame_progress,
    load_scene,
    material_height,
    progress,
)
from triaxtrack.simulate.truth import finish_truth, target_positions, truth_volume

__all__ = [
    "BOARD_ANCHORS", "BOARD_CORNER_DISTANCE_MM", "BOARD_CORNER_INSET_PX", "BOARD_CORNER_MIN_LINES",
    "BOARD_CORNER_MIN_SEEN", "BOARD_CORNER_ORDER", "BOARD_CORNER_SEEN_PX", "BOARD_CORNER_SHARE",
    "BOARD_DISTANCE_MM", "BOARD_EDGE_PX", "BOARD_MAX_TRIES", "BOARD_MAX_VIEW_DEG", "BOARD_ROLL_DEG",
    "BOARD_SHIFT_STEPS", "BOARD_TILT_DEG", "CHECK_SAMPLE", "CameraRenderer", "EDGE_MARGIN_PX",
    "GREY_BACKGROUND", "GREY_INK", "GREY_LABEL", "GREY_MEMBRANE", "GREY_OCCLUDER", "GREY_PEDESTAL_FACE",
    "GREY_PEDESTAL_SIDE", "JITTER_ANGLE_DEG", "JITTER_FOCAL_REL", "JITTER_K1", "JITTER_K2", "JITTER_P",
    "JITTER_POSITION_MM", "JITTER_PRINCIPAL_REL", "JITTER_ROTATION_DEG", "MAX_TILT_DEG", "MEMBRANE_QUADS",
    "NVR_LENS_BLUR_PX", "OCCLUDER_NEWTON_STEPS", "OCCLUDER_QUADS", "OCCLUDER_ROW_MM", "OCCLUSION_TOL",
    "PEDESTAL_QUADS", "PRESETS", "SUBROWS_INK", "SUBROWS_PLAIN", "Scene", "SimulationConfig", "TILT_STREAM",
    "VIGNETTING", "apply_preset", "board_poses", "camera_names", "camera_pitch_deg", "centroid_errors",
    "check_loading_history", "check_simulation", "corner_board_count", "deformation_for", "finish_truth",
    "frame_progress", "gop_frames", "load_scene", "loading_progress", "look_at",
    "make_cameras", "make_scene", "material_height", "progress", "recorded_frames", "render_board_image",
    "render_calibration", "render_chunk", "render_segments", "simulate_test", "target_positions",
    "tilt_rotation", "truth_volume",
]  # fmt: skip
