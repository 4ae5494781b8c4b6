"""Camera calibration from rendered checkerboard images, against the simulator's exact truth."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from triaxtrack.calibrate import (
    CalibrationConfig,
    CalibrationError,
    board_pattern,
    calibrate_camera,
    canonical_corner_order,
    find_board_corners,
    read_board,
)
from triaxtrack.cli import main
from triaxtrack.optics import Camera, normalized_to_pixels, pixels_to_normalized, read_cameras
from triaxtrack.score import ScoreTolerances, pixel_grid, score, undistortion_map_error
from triaxtrack.simulate import SimulationConfig, make_scene, render_calibration

CAMERAS = ("cam01", "cam02")
TOL = ScoreTolerances()
# The undistortion map (ray direction through every pixel, image corners included) is not
# recovered to TOL.undistortion_px (0.1 px) from 12 boards: corner noise of ~0.02 px leaves
# ~0.1 px in the principal point, and the image corners lie beyond the last board corner
# (measured here: 0.38 and 0.30 px). This bound catches a broken calibration, not a marginal one.
UNDISTORTION_BOUND_PX = 1.0


@pytest.fixture(scope="module")
def boards(kit_dir, tmp_path_factory) -> Path:
    """A 3-camera scene at 960x540; 12 board images each for cam01 and cam02."""
    out = tmp_path_factory.mktemp("calibrate") / "test"
    make_scene(
        SimulationConfig(cameras=3, frames=2, width=960, height=540, calibration_images=12),
        kit_dir,
        out,
        "cal",
    )
    for cam in CAMERAS:
        render_calibration(out, cam, out / "calibration" / cam)
    return out


@pytest.fixture(scope="module")
def calibrations(boards) -> dict[str, dict]:
    return {
        cam: calibrate_camera(cam, boards / "calibration" / cam, boards / "kit", CalibrationConfig())
        for cam in CAMERAS
    }


def as_camera(cal: dict) -> Camera:
    return Camera(
        cal["camera"],
        cal["width"],
        cal["height"],
        np.array(cal["K"]),
        np.array(cal["dist"]),
        np.eye(3),
        np.zeros(3),
    )


def true_corners(test_dir: Path, camera: str) -> dict[str, np.ndarray]:
    poses = json.loads((test_dir / "truth" / "calibration" / f"{camera}.json").read_text())["board_poses"]
    return {p["image"]: np.array(p["corners_px"]) for p in poses}


def test_corners_are_found_in_board_order(boards):
    """Every detected corner is the true image of the board corner of the same index
    (kit.board_corners_mm order), to well under a tenth of a pixel."""
    board = read_board(boards / "kit")
    errs = []
    for name, truth in true_corners(boards, "cam01").items():
        gray = cv2.imread(str(boards / "calibration" / "cam01" / name), cv2.IMREAD_GRAYSCALE)
        found = find_board_corners(gray, board)
        assert found is not None, name
        errs.append(np.linalg.norm(found - truth, axis=1))
    errs = np.concatenate(errs)
    assert np.sqrt(np.mean(errs**2)) < 0.04 and errs.max() < 0.15, (np.sqrt(np.mean(errs**2)), errs.max())


def test_corner_order_survives_a_half_turn_and_a_mirrored_reading(boards):
    """The board (10 x 7 squares) is told from its 180-degree turn by the colour of its squares,
    and a reading with the wrong handedness is turned back."""
    board = read_board(boards / "kit")
    nx, ny = board_pattern(board)
    name, truth = next(iter(true_corners(boards, "cam02").items()))
    gray = cv2.imread(str(boards / "calibration" / "cam02" / name), cv2.IMREAD_GRAYSCALE)
    h, w = gray.shape
    turned = find_board_corners(np.ascontiguousarray(gray[::-1, ::-1]), board)
    assert np.abs(turned - ((w - 1, h - 1) - truth)).max() < 0.15
    for reading in (
        truth[::-1],
        truth.reshape(ny, nx, 2)[::-1].reshape(-1, 2),
        truth.reshape(ny, nx, 2)[:, ::-1],
    ):
        np.testing.assert_allclose(canonical_corner_order(gray, reading.reshape(-1, 2), (nx, ny)), truth)


def test_calibration_recovers_the_true_camera(boards, calibrations):
    truth = read_cameras(boards / "truth" / "cameras.json")
    for cam, cal in calibrations.items():
        est, tr = as_camera(cal), truth[cam]
        assert (cal["width"], cal["height"], cal["model"], len(cal["dist"])) == (960, 540, "standard", 5)
        assert cal["n_images"] == cal["n_images_found"] == cal["n_images_used"] == 12
        assert all(im["used"] and im["reason"] == "" and im["rms_px"] < 0.1 for im in cal["images"])
        assert cal["rms_px"] < 0.05
        focal = max(abs(est.K[0, 0] / tr.K[0, 0] - 1), abs(est.K[1, 1] / tr.K[1, 1] - 1))
        assert focal < TOL.focal_rel, (cam, focal)
        assert np.hypot(*(est.K[:2, 2] - tr.K[:2, 2])) < TOL.principal_point_px
        assert undistortion_map_error(est, tr) < UNDISTORTION_BOUND_PX


def test_outlier_and_boardless_images_are_named(boards, tmp_path):
    """A warped image (its corners no longer fit any camera) is rejected as an outlier, an image
    without the board is reported, and the camera still calibrates from the rest."""
    folder = tmp_path / "cam01"
    shutil.copytree(boards / "calibration" / "cam01", folder)
    gray = cv2.imread(str(folder / "03.png"), cv2.IMREAD_GRAYSCALE)
    h, w = gray.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    warp_u = xx + 2.0 * np.sin(2 * np.pi * yy / 200)  # smooth enough for the board to be found
    warp_v = yy + 2.0 * np.cos(2 * np.pi * xx / 250)
    cv2.imwrite(str(folder / "03.png"), cv2.remap(gray, warp_u, warp_v, cv2.INTER_CUBIC))
    cv2.imwrite(str(folder / "99.png"), np.full((h, w), 120, np.uint8))
    cal = calibrate_camera("cam01", folder, boards / "kit", CalibrationConfig())
    images = {im["image"]: im for im in cal["images"]}
    assert (cal["n_images"], cal["n_images_found"], cal["n_images_used"]) == (13, 12, 11)
    assert not images["03.png"]["used"] and images["03.png"]["reason"].startswith("outlier")
    assert images["03.png"]["rms_px"] > cal["outlier_limit_px"]
    assert images["99.png"] == {"image": "99.png", "rms_px": None, "used": False, "reason": "board not found"}
    assert [name for name, im in images.items() if not im["used"]] == ["03.png", "99.png"]
    tr = read_cameras(boards / "truth" / "cameras.json")["cam01"]
    assert abs(cal["K"][0][0] / tr.K[0, 0] - 1) < TOL.focal_rel


def test_missing_unreadable_and_too_few_images_name_camera_and_file(boards, tmp_path):
    kit, cfg = boards / "kit", CalibrationConfig()
    with pytest.raises(CalibrationError, match=r"camera cam01: calibration folder .*nowhere not found"):
        calibrate_camera("cam01", tmp_path / "nowhere", kit, cfg)
    (tmp_path / "empty").mkdir()
    with pytest.raises(CalibrationError, match=r"camera cam01: no board images \(\*\.png\) in .*empty"):
        calibrate_camera("cam01", tmp_path / "empty", kit, cfg)
    few = tmp_path / "few"
    few.mkdir()
    for name in ("01.png", "02.png", "03.png", "04.png", "05.png", "06.png", "07.png"):
        shutil.copy(boards / "calibration" / "cam01" / name, few)
    cv2.imwrite(str(few / "08.png"), np.zeros((540, 960), np.uint8))
    with pytest.raises(
        CalibrationError, match=r"camera cam01: 7 usable board images of 8 in .*few, at least 8"
    ):
        calibrate_camera("cam01", few, kit, cfg)
    (few / "09.png").write_bytes(b"not a png")
    with pytest.raises(CalibrationError, match=r"camera cam01: cannot read board image .*09\.png"):
        calibrate_camera("cam01", few, kit, cfg)


def test_config_is_checked():
    assert CalibrationConfig.from_dict({"model": "rational"}).model == "rational"
    with pytest.raises(ValueError, match="model"):
        CalibrationConfig.from_dict({"model": "fisheye"})
    with pytest.raises(ValueError, match="unknown calibration settings"):
        CalibrationConfig.from_dict({"min_image": 3})


# ---------------------------------------------------------------- undistortion and scoring


def test_undistortion_inverts_strong_distortion_to_1e_3_px():
    """pixels_to_normalized iterates cv2.undistortPoints to convergence: re-distorting its
    result returns every pixel of a k1 = -0.3 lens (corners included) within 1e-3 px, where
    undistortPoints' default 5 iterations miss by a large fraction of a pixel."""
    K = np.array([[794.0, 0, 641.3], [0, 794.0, 358.2], [0, 0, 1]])
    cam = Camera("c", 1280, 720, K, np.array([-0.3, 0.08, 2e-4, -1e-4, 0.0]), np.eye(3), np.zeros(3))
    uv = pixel_grid(1280, 720)
    assert len(uv) == 161 * 91 and uv.max(axis=0).tolist() == [1279.0, 719.0]
    back = normalized_to_pixels(cam, pixels_to_normalized(cam, uv))
    assert np.abs(back - uv).max() < 1e-3
    default = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, cam.dist).reshape(-1, 2)
    assert np.abs(normalized_to_pixels(cam, default) - uv).max() > 0.1


def test_undistortion_map_error_sees_focal_and_distortion_errors():
    K = np.array([[794.0, 0, 639.5], [0, 794.0, 359.5], [0, 0, 1]])
    tr = Camera("c", 1280, 720, K, np.array([-0.3, 0.08, 0, 0, 0.0]), np.eye(3), np.zeros(3))
    assert undistortion_map_error(tr, tr) < 1e-9
    shifted = Camera("c", 1280, 720, K + [[0, 0, 0.3], [0, 0, 0], [0, 0, 0]], tr.dist, np.eye(3), np.zeros(3))
    # a principal point 0.3 px off moves every ray by 0.3 px at the centre, by more towards the
    # corners (where undistortion stretches the image by up to 2x)
    assert 0.3 < undistortion_map_error(shifted, tr) < 0.7
    k3 = Camera("c", 1280, 720, K, np.array([-0.3, 0.08, 0, 0, 1e-3]), np.eye(3), np.zeros(3))
    assert undistortion_map_error(k3, tr) > 0.5  # k3 shows at the image corners


def test_score_reports_calibrations_per_camera(boards, calibrations, tmp_path):
    results = tmp_path / "results"
    (results / "calibration").mkdir(parents=True)
    for cam, cal in calibrations.items():
        (results / "calibration" / f"{cam}.json").write_text(json.dumps(cal))
    df = score(results, boards, TOL)
    rows = {(r.metric, r.item): r for r in df.itertuples()}
    for cam in CAMERAS:
        assert rows[("focal_rel_error", cam)].passed and rows[("principal_point_error", cam)].passed
        umap = rows[("undistortion_map_error", cam)]
        assert (
            umap.tolerance == TOL.undistortion_px
            and umap.unit == "px"
            and umap.source == f"calibration/{cam}.json"
        )
        assert umap.value == pytest.approx(
            undistortion_map_error(
                as_camera(calibrations[cam]), read_cameras(boards / "truth" / "cameras.json")[cam]
            )
        )
    assert not rows[("camera_missing", "cam03")].passed  # cam03 was not calibrated
    assert main(["score", str(results), str(boards)]) == 1
    # perfect calibrations (the truth itself) pass everything
    perfect = tmp_path / "perfect"
    (perfect / "calibration").mkdir(parents=True)
    for cam, tr in read_cameras(boards / "truth" / "cameras.json").items():
        cal = {
            "camera": cam,
            "width": tr.width,
            "height": tr.height,
            "K": tr.K.tolist(),
            "dist": tr.dist.tolist(),
        }
        (perfect / "calibration" / f"{cam}.json").write_text(json.dumps(cal))
    df = score(perfect, boards, TOL)
    assert df.passed.all() and set(df.metric) == {
        "focal_rel_error",
        "principal_point_error",
        "undistortion_map_error",
    }
    (perfect / "calibration" / "cam02.json").write_text("{}")
    with pytest.raises(ValueError, match=r"cam02\.json: not a calibration result"):
        score(perfect, boards, TOL)
