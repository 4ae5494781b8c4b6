"""Camera calibration from rendered checkerboard images, against the simulator's exact truth."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from triaxtrack.calibrate import (
    BoardImage,
    CalibrationConfig,
    CalibrationError,
    board_pattern,
    calibrate_camera,
    canonical_corner_order,
    consistent_corners,
    find_board,
    find_board_corners,
    fit_views,
    grid_indices,
    neighbour_spacing_px,
    read_board,
    refine_view,
)
from triaxtrack.cli import main
from triaxtrack.kit import board_corners_mm, load_design
from triaxtrack.kit_design import BoardDesign
from triaxtrack.optics import (
    Camera,
    normalized_to_pixels,
    pixels_to_normalized,
    pixels_to_undistorted,
    project_air,
    read_cameras,
)
from triaxtrack.score import ScoreTolerances, score
from triaxtrack.score_cameras import pixel_grid, ray_direction_error, undistortion_map_error
from triaxtrack.simulate import SimulationConfig, board_poses, make_cameras, make_scene, render_calibration

CAMERAS = ("cam01", "cam02")
TOL = ScoreTolerances()
# 12 board images at 960x540: 8 whole boards and 4 running off the image across its corners
# (simulate.board_poses). Measured when written: undistortion map 0.035 and 0.016 px (cam01,
# cam02), principal point 0.002 and 0.03 px, focal 2e-5; corners 0.012 px RMS (first pass) and
# 0.007 px (second pass, through the lens), against the exact projections
UNDISTORTION_BOUND_PX = 0.06


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


def true_poses(test_dir: Path, camera: str) -> list[dict]:
    return json.loads((test_dir / "truth" / "calibration" / f"{camera}.json").read_text())["board_poses"]


def true_corners(test_dir: Path, camera: str, kind: str = "whole") -> dict[str, np.ndarray]:
    return {p["image"]: np.array(p["corners_px"]) for p in true_poses(test_dir, camera) if p["kind"] == kind}


def gray(test_dir: Path, camera: str, image: str) -> np.ndarray:
    return cv2.imread(str(test_dir / "calibration" / camera / image), cv2.IMREAD_GRAYSCALE)


def matched(found_px: np.ndarray, truth_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest true corner of each found corner, and the distance to it (px)."""
    d = np.linalg.norm(found_px[:, None] - truth_px[None], axis=2)
    return d.argmin(axis=1), d.min(axis=1)


def test_corners_are_found_in_board_order(boards):
    """Every detected corner of a whole board is the true image of the board corner of the same
    index (kit.board_corners_mm order), to about a hundredth of a pixel (first pass: the
    point-symmetry fit in the image)."""
    board = read_board(boards / "kit")
    errs = []
    for name, truth in true_corners(boards, "cam01").items():
        found = find_board_corners(gray(boards, "cam01", name), board)
        if found is not None:  # a whole board may be taken as a partial one (next test)
            errs.append(np.linalg.norm(found - truth, axis=1))
    assert len(errs) >= 6
    errs = np.concatenate(errs)
    rms = np.sqrt(np.mean(errs**2))
    assert rms < 0.02 and errs.max() < 0.06, (rms, errs.max())


def test_partial_boards_are_found_with_consistent_indices(boards):
    """A board running off the image across an image corner is found from the part seen: its
    corners are true corners (within 0.1 px), at least 70 % of those 8 px or more inside the
    image, and their own grid indices are the board's up to one rotation, reflection and shift
    (a wrong index would be a whole square off)."""
    board = read_board(boards / "kit")
    nx, _ = board_pattern(board)
    for cam in CAMERAS:
        for name, truth in true_corners(boards, cam, "corner").items():
            h, w = gray(boards, cam, name).shape
            view = find_board(gray(boards, cam, name), board, name)
            assert view.image == name and view.kind == "partial", (cam, name, view.kind)
            seen = ((truth >= 8) & (truth <= [w - 9, h - 9])).all(axis=1).sum()
            assert len(view.corners_px) >= 0.7 * seen, (cam, name, len(view.corners_px), seen)
            idx, dist = matched(view.corners_px, truth)
            assert dist.max() < 0.1 and len(set(idx)) == len(idx), (cam, name, dist.max())
            own = grid_indices(view.object_mm, board.square_mm)
            board_ij = np.c_[idx % nx, idx // nx]
            A, *_ = np.linalg.lstsq(np.c_[own, np.ones(len(own))], board_ij, rcond=None)
            np.testing.assert_allclose(np.c_[own, np.ones(len(own))] @ A, board_ij, atol=1e-6)
            assert sorted(np.abs(np.round(A[:2])).ravel().tolist()) == [0, 0, 1, 1]


def test_second_pass_refines_through_the_lens(boards, calibrations):
    """Refined again with windows drawn in undistorted coordinates (the first calibration's
    lens), the corners come closer to the truth: lines bent by the distortion are not
    point-symmetric, which biases the first pass near the image edges."""
    board = read_board(boards / "kit")
    cal = calibrations["cam01"]
    K, dist = np.array(cal["K"]), np.array(cal["dist"])
    first, second = [], []
    for name, truth in {**true_corners(boards, "cam01"), **true_corners(boards, "cam01", "corner")}.items():
        image = gray(boards, "cam01", name)
        view = find_board(image, board, name)
        uv, _ = refine_view(image, view.corners_px, view.object_mm, board.square_mm, K, dist)
        first.append(matched(view.corners_px, truth)[1])
        second.append(matched(uv, truth)[1])
    first, second = np.concatenate(first), np.concatenate(second)
    rms1, rms2 = np.sqrt(np.mean(first**2)), np.sqrt(np.mean(second**2))
    assert rms2 < 0.01 and rms2 < 0.8 * rms1, (rms1, rms2)
    assert len(second) >= 0.98 * len(first)


def test_grid_checks_catch_a_corner_a_square_off():
    """neighbour_spacing_px measures each corner's nearest grid neighbour; consistent_corners
    drops a corner placed one square away from where its neighbours put it, and only it."""
    r, c = np.mgrid[0:5, 0:6]
    grid = np.stack([40.0 + 20 * c + 0.3 * r * c, 30.0 + 18 * r], axis=-1)  # mild perspective
    obj = np.c_[c.ravel(), r.ravel(), np.zeros(30)] * 12.5
    spacing = neighbour_spacing_px(grid.reshape(-1, 2), obj, 12.5)
    assert spacing.min() == pytest.approx(18.0) and spacing.max() <= 20.0 + 0.3 * 4
    assert consistent_corners(grid).all()
    bad = grid.copy()
    bad[2, 3] = grid[2, 4]  # the corner of the next column, given this one's index
    ok = consistent_corners(bad)
    assert not ok[2, 3] and ok.sum() == 29


def _board_views(cfg: SimulationConfig, cam: Camera, board: BoardDesign, noise: float) -> list[BoardImage]:
    """20 board views of ``cam`` (at the origin) from :func:`board_poses`: exact corners plus
    ``noise`` px, whole boards in the board's frame and partial ones in their own grid frame
    (a quarter turn and a shift of the board's)."""
    obj = board_corners_mm(board)
    w, h = cam.width, cam.height
    rng = np.random.default_rng(0)
    views = []
    for i, (R, t) in enumerate(board_poses(cfg, cam, board, 20)):
        uv = project_air(Camera("b", w, h, cam.K, cam.dist, R, t), obj)
        seen = ((uv >= 8) & (uv <= [w - 9, h - 9])).all(axis=1)
        uv = uv + rng.normal(0, noise, uv.shape)
        if seen.all():
            views.append(BoardImage(f"{i}", uv, obj, whole=True))
        else:
            ij = grid_indices(obj[seen], board.square_mm)
            own = np.c_[-ij[:, 1] + 7, ij[:, 0] - 3, np.zeros(len(ij))] * board.square_mm
            views.append(BoardImage(f"{i}", uv[seen], own, whole=False))
    return views


def test_two_stage_fit_with_partial_views_in_their_own_frames():
    """fit_views fits the whole boards first, then every view from there. Partial views whose
    object points are in their own grid frame (a quarter turn and a shift of the board's)
    reproduce the camera exactly from exact corners; with 0.005 px noise they bring the
    undistortion map within 0.03 px (0.009-0.029 px when written; whole boards alone:
    0.04-0.23 px)."""
    board = load_design(Path(__file__).resolve().parents[1] / "config" / "kit.yaml").board
    cfg = SimulationConfig(cameras=3, width=960, height=540)
    size = (960, 540)
    for cam in make_cameras(cfg):
        cam0 = Camera(cam.name, 960, 540, cam.K, cam.dist, np.eye(3), np.zeros(3))
        for noise, bound in ((0.0, 1e-3), (0.005, 0.03)):
            views = _board_views(cfg, cam0, board, noise)
            assert sum(v.whole for v in views) == 12
            _, K, dist, per_view = fit_views(views, board, size, "standard")
            assert len(dist) == 5 and len(per_view) == 20
            est = Camera("e", 960, 540, K, dist, np.eye(3), np.zeros(3))
            assert undistortion_map_error(est, cam0) < bound, (cam.name, noise)
            if noise:
                _, K, dist, _ = fit_views([v for v in views if v.whole], board, size, "standard")
                whole_only = Camera("e", 960, 540, K, dist, np.eye(3), np.zeros(3))
                assert undistortion_map_error(whole_only, cam0) > undistortion_map_error(est, cam0)


def test_boards_are_placed_and_fitted_for_a_wider_more_distorted_lens():
    """A lens wider and more distorted than the simulator's default (focal 0.56 x the width,
    k1 -0.4, k2 0.125): every board is placed (the corner boards' Newton steps go on until their
    anchor lands: 4 left it 4.6-4.9 px off and no pose was found), and the two-stage fit of
    their corners with 0.005 px of noise reproduces the undistortion map (0.011 px when written)."""
    board = load_design(Path(__file__).resolve().parents[1] / "config" / "kit.yaml").board
    f = 0.56 * 1280
    K = np.array([[f, 0, 639.5], [0, f, 359.5], [0, 0, 1]])
    cam = Camera("c", 1280, 720, K, np.array([-0.4, 0.125, 0, 0, 0.0]), np.eye(3), np.zeros(3))
    views = _board_views(SimulationConfig(), cam, board, 0.005)
    assert len(views) == 20 and sum(v.whole for v in views) == 12
    _, K_est, dist, _ = fit_views(views, board, (1280, 720), "standard")
    assert undistortion_map_error(Camera("e", 1280, 720, K_est, dist, np.eye(3), np.zeros(3)), cam) < 0.03


def test_two_stage_fit_starts_from_the_whole_boards(monkeypatch):
    """The first cv2.calibrateCameraExtended call sees the whole boards only, the second every
    view, from the first's intrinsics (CALIB_USE_INTRINSIC_GUESS)."""
    import triaxtrack.calibrate.fit as calibrate

    calls = []
    real = cv2.calibrateCameraExtended

    def spy(obj, img, size, K, dist, flags, criteria):
        calls.append((len(obj), bool(flags & cv2.CALIB_USE_INTRINSIC_GUESS), K is not None))
        return real(obj, img, size, K, dist, flags=flags, criteria=criteria)

    monkeypatch.setattr(calibrate.cv2, "calibrateCameraExtended", spy)
    K = np.array([[600.0, 0, 479.5], [0, 600.0, 269.5], [0, 0, 1]])
    cam = Camera("c", 960, 540, K, np.array([-0.3, 0.08, 0, 0, 0.0]), np.eye(3), np.zeros(3))
    board = BoardDesign(squares_x=16, squares_y=11, square_mm=12.5, margin_mm=20.0)
    obj = board_corners_mm(board)
    views = []
    for i, (R, t) in enumerate(board_poses(SimulationConfig(), cam, board, 12)):
        uv = project_air(Camera("b", 960, 540, K, cam.dist, R, t), obj)
        seen = ((uv >= 8) & (uv <= [951, 531])).all(axis=1)
        views.append(BoardImage(f"{i}", uv[seen], obj[seen], whole=bool(seen.all())))
    n_whole = sum(v.whole for v in views)
    assert 3 <= n_whole < 12
    fit_views(views, board, (960, 540), "standard")
    assert calls == [(n_whole, False, False), (12, True, True)]
    calls.clear()
    fit_views([v for v in views if v.whole], board, (960, 540), "standard")
    assert calls == [(n_whole, False, False)]  # whole boards only: one fit from scratch


def test_corner_order_survives_a_half_turn_and_a_mirrored_reading(boards):
    """The board (16 x 11 squares) is told from its 180-degree turn by the colour of its squares,
    and a reading with the wrong handedness is turned back."""
    board = read_board(boards / "kit")
    nx, ny = board_pattern(board)
    name, truth = next(iter(true_corners(boards, "cam02").items()))
    image = gray(boards, "cam02", name)
    h, w = image.shape
    turned = find_board_corners(np.ascontiguousarray(image[::-1, ::-1]), board)
    assert np.abs(turned - ((w - 1, h - 1) - truth)).max() < 0.1
    for reading in (
        truth[::-1],
        truth.reshape(ny, nx, 2)[::-1].reshape(-1, 2),
        truth.reshape(ny, nx, 2)[:, ::-1],
    ):
        np.testing.assert_allclose(canonical_corner_order(image, reading.reshape(-1, 2), (nx, ny)), truth)


def test_calibration_recovers_the_true_camera(boards, calibrations):
    """Whole and partial boards, two passes: focal length, principal point and the undistortion
    map within the score's tolerances (the map with room to spare: UNDISTORTION_BOUND_PX)."""
    truth = read_cameras(boards / "truth" / "cameras.json")
    for cam, cal in calibrations.items():
        est, tr = as_camera(cal), truth[cam]
        assert (cal["width"], cal["height"], cal["model"], len(cal["dist"])) == (960, 540, "standard", 5)
        assert cal["n_images"] == cal["n_images_found"] == cal["n_images_used"] == 12 and cal["passes"] == 2
        assert all(im["used"] and im["reason"] == "" and im["rms_px"] < 0.03 for im in cal["images"])
        kinds = [im["board"] for im in cal["images"]]
        assert (
            kinds[8:] == ["partial"] * 4 and kinds.count("whole") >= 6
        )  # a whole board may be read as partial
        assert all(im["n_corners"] == 150 for im in cal["images"][:8])
        assert all(20 <= im["n_corners"] < 150 for im in cal["images"][8:])
        assert cal["n_corners_used"] == sum(im["n_corners"] for im in cal["images"])
        assert cal["rms_px"] < 0.02
        focal = max(abs(est.K[0, 0] / tr.K[0, 0] - 1), abs(est.K[1, 1] / tr.K[1, 1] - 1))
        assert focal < TOL.focal_rel / 10, (cam, focal)
        assert np.hypot(*(est.K[:2, 2] - tr.K[:2, 2])) < TOL.principal_point_px / 10
        assert undistortion_map_error(est, tr) < UNDISTORTION_BOUND_PX, (cam, undistortion_map_error(est, tr))


def test_one_pass_is_worse_than_two(boards, calibrations):
    """Without the second corner pass the camera is still calibrated, less well: the corners
    near the image edges keep the lens's bias, and the distortion fit carries it to the image
    corners."""
    tr = read_cameras(boards / "truth" / "cameras.json")["cam01"]
    one = calibrate_camera(
        "cam01", boards / "calibration" / "cam01", boards / "kit", CalibrationConfig(passes=1)
    )
    assert one["passes"] == 1 and one["n_images_used"] == 12
    assert one["rms_px"] > calibrations["cam01"]["rms_px"]
    one_pass = undistortion_map_error(as_camera(one), tr)  # 0.20 px when written (two: 0.03)
    assert undistortion_map_error(as_camera(calibrations["cam01"]), tr) < one_pass / 2 and one_pass < 0.5


def test_outlier_and_boardless_images_are_named(boards, tmp_path):
    """A warped image (its corners no longer fit any camera) is rejected as an outlier, an image
    without the board is reported, and the camera still calibrates from the rest."""
    folder = tmp_path / "cam01"
    shutil.copytree(boards / "calibration" / "cam01", folder)
    image = gray(boards, "cam01", "03.png")
    h, w = image.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    warp_u = xx + 2.0 * np.sin(2 * np.pi * yy / 200)  # smooth enough for the board to be found
    warp_v = yy + 2.0 * np.cos(2 * np.pi * xx / 250)
    cv2.imwrite(str(folder / "03.png"), cv2.remap(image, warp_u, warp_v, cv2.INTER_CUBIC))
    cv2.imwrite(str(folder / "99.png"), np.full((h, w), 120, np.uint8))
    cal = calibrate_camera("cam01", folder, boards / "kit", CalibrationConfig())
    images = {im["image"]: im for im in cal["images"]}
    assert (cal["n_images"], cal["n_images_found"], cal["n_images_used"]) == (13, 12, 11)
    assert not images["03.png"]["used"] and images["03.png"]["reason"].startswith("outlier")
    assert images["03.png"]["rms_px"] > cal["outlier_limit_px"]
    assert images["99.png"] == {
        "image": "99.png",
        "board": None,
        "n_corners": 0,
        "rms_px": None,
        "used": False,
        "reason": "board not found",
    }
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
    assert CalibrationConfig.from_dict(None).passes == 2
    with pytest.raises(ValueError, match="model"):
        CalibrationConfig.from_dict({"model": "fisheye"})
    with pytest.raises(ValueError, match="passes"):
        CalibrationConfig.from_dict({"passes": 3})
    with pytest.raises(ValueError, match=r"calibration: unknown key 'min_image' \(did you mean 'min_images'"):
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
    """The undistortion map (pixel to undistorted pixel, each camera in its own K) sees a focal
    or distortion error; a principal-point shift moves it only where the map is not a plain
    shift (the image corners), while the ray direction moves by the shift everywhere and by
    about twice it at the corners."""
    K = np.array([[794.0, 0, 639.5], [0, 794.0, 359.5], [0, 0, 1]])

    def camera(dK=0.0, dist=(-0.3, 0.08, 0, 0, 0.0)) -> Camera:
        return Camera("c", 1280, 720, K + dK, np.array(dist), np.eye(3), np.zeros(3))

    tr = camera()
    assert undistortion_map_error(tr, tr) < 1e-9 and ray_direction_error(tr, tr) < 1e-9
    shifted = camera(np.array([[0, 0, 0.3], [0, 0, 0], [0, 0, 0]]))
    assert 0.25 < undistortion_map_error(shifted, tr) < 0.35  # 0.307 at the image corners
    assert 0.55 < ray_direction_error(shifted, tr) < 0.65  # 0.3 at the centre, 0.607 at the corners

    centre = [[639.5, 359.5]]  # where the two maps agree
    assert np.linalg.norm(pixels_to_undistorted(shifted, centre) - pixels_to_undistorted(tr, centre)) < 1e-3
    focal = camera(np.diag([0.794, 0.794, 0.0]))  # 0.1 %
    assert 0.4 < undistortion_map_error(focal, tr) < 0.5
    k3 = camera(dist=(-0.3, 0.08, 0, 0, 1e-3))
    assert undistortion_map_error(k3, tr) > 5  # k3 shows at the image corners


def test_score_reports_calibrations_per_camera(boards, calibrations, tmp_path):
    results = tmp_path / "results"
    (results / "calibration").mkdir(parents=True)
    for cam, cal in calibrations.items():
        (results / "calibration" / f"{cam}.json").write_text(json.dumps(cal))
    df = score(results, boards, TOL)
    rows = {(r.metric, r.item): r for r in df.itertuples()}
    truth = read_cameras(boards / "truth" / "cameras.json")
    for cam in CAMERAS:
        assert rows[("focal_rel_error", cam)].passed and rows[("principal_point_error", cam)].passed
        umap = rows[("undistortion_map_error", cam)]
        assert (
            umap.tolerance == TOL.undistortion_px
            and umap.unit == "px"
            and umap.source == f"calibration/{cam}.json"
            and umap.passed
        )
        assert umap.value == pytest.approx(undistortion_map_error(as_camera(calibrations[cam]), truth[cam]))
        ray = rows[("ray_direction_error", cam)]
        assert np.isnan(ray.tolerance) and ray.passed and ray.unit == "px"
        assert ray.value == pytest.approx(ray_direction_error(as_camera(calibrations[cam]), truth[cam]))
    assert not rows[("camera_missing", "cam03")].passed  # cam03 was not calibrated
    assert main(["score", str(results), str(boards)]) == 1
    # perfect calibrations (the truth itself) pass everything
    perfect = tmp_path / "perfect"
    (perfect / "calibration").mkdir(parents=True)
    for cam, tr in truth.items():
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
        "ray_direction_error",
    }
    (perfect / "calibration" / "cam02.json").write_text("{}")
    with pytest.raises(ValueError, match=r"cam02\.json: not a calibration result"):
        score(perfect, boards, TOL)
