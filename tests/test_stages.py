"""The workflow's stage entry points (``run_<rule>``) on small synthetic files: what each reads,
writes and carries from one file to the next.

The first frame (reconstruct_cell, trace_specimen) and the timesteps (triangulate_chunk,
collect_timesteps) run on the synthetic scene of ``test_reconstruct`` (the default ring of 13
cameras, the kit's targets projected exactly plus 0.05 px of noise), written to files; identify
and track run on one camera of the small simulated test of ``conftest``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from test_reconstruct import _observations  # noisy labels of the synthetic scene

from triaxtrack.frames import run_frame_map
from triaxtrack.identify import run_identify_targets
from triaxtrack.jsonfile import read_json, write_json
from triaxtrack.kit import design_points
from triaxtrack.optics import cell_optics, read_cameras
from triaxtrack.sfm import REFERENCE_FRAME
from triaxtrack.sfm_stage import run_reconstruct_cell
from triaxtrack.simulate import SimulationConfig, make_cameras
from triaxtrack.specimen_stage import run_trace_specimen
from triaxtrack.tables import FRAME_MAP, LABELS, OBSERVATIONS, POINTS, TRACKS, read_table, write_table
from triaxtrack.testfolder import read_test_fps, read_test_yaml
from triaxtrack.timesteps import MOTION, run_collect_timesteps, run_triangulate_chunk
from triaxtrack.track_stage import run_track_targets

ROOT = Path(__file__).resolve().parents[1]
CONFIG = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
FPS = 15.0
WAVELENGTH_NM = 633.0  # given in the config's cell section: quality.json must say so
KNOCK_PX = 3.0  # a camera knocked by this much (its cell-wall targets' drift) has moved


# ---------------------------------------------------------------- the files' owners


def test_test_yaml_fps_and_errors_name_the_file(tmp_path):
    path = tmp_path / "test.yaml"
    path.write_text(yaml.safe_dump({"name": "t", "fps": 25, "cameras": ["a"]}))
    assert read_test_fps(path) == 25.0 and read_test_yaml(path)["cameras"] == ["a"]
    path.write_text(yaml.safe_dump({"name": "t", "cameras": ["a"]}))
    with pytest.raises(ValueError, match=r"test\.yaml: test\.yaml has no usable fps"):
        read_test_fps(path)
    path.write_text("- just\n- a list\n")
    with pytest.raises(ValueError, match=r"test\.yaml: not a readable test\.yaml: not a mapping"):
        read_test_yaml(path)
    with pytest.raises(ValueError, match=r"absent\.yaml: not a readable test\.yaml"):
        read_test_fps(tmp_path / "absent.yaml")


def test_json_documents_are_written_as_json_dump_and_read_errors_name_the_file(tmp_path):
    doc = {"b": [1.5, float("nan"), None], "a": {"x": "y"}}
    write_json(tmp_path / "doc.json", doc)
    assert (tmp_path / "doc.json").read_text() == json.dumps(doc, indent=2)
    assert list(read_json(tmp_path / "doc.json", "doc")) == ["b", "a"]
    write_json(tmp_path / "sorted.json", doc, sort_keys=True)
    text = (tmp_path / "sorted.json").read_text()
    assert text == json.dumps(doc, indent=2, sort_keys=True) and text.index('"a"') < text.index('"b"')
    (tmp_path / "bad.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"bad\.json: not a readable cell\.json: not a JSON object"):
        read_json(tmp_path / "bad.json", "cell.json")
    with pytest.raises(ValueError, match=r"none\.json: not a readable quality\.json"):
        read_json(tmp_path / "none.json", "quality.json")


# ---------------------------------------------------------------- the first frame from files


def _labels_table(observations: pd.DataFrame, table: pd.DataFrame) -> pd.DataFrame:
    """``LABELS`` rows of noisy observations ``camera, frame, id, u_px, v_px``."""
    kind = table.set_index("id")["kind"]
    return observations.assign(
        kind=kind.reindex(observations["id"]).to_numpy(), group="", u_undist_px=np.nan, v_undist_px=np.nan,
        area_px=np.nan, roundness=np.nan, quality=1.0, reason="",
    )  # fmt: skip


@pytest.fixture(scope="module")
def first_frame(design, table, kit_dir, tmp_path_factory) -> dict:
    """The synthetic scene's calibrations, labels and test.yaml as files, then
    run_reconstruct_cell and run_trace_specimen on them: every path, and the truth."""
    out = tmp_path_factory.mktemp("first_frame")
    cameras = make_cameras(SimulationConfig())
    truth = design_points(design, table)
    observed = _observations(cameras, truth, table, cell_optics(design), np.random.default_rng(7))
    paths = {"labels": out / "labels.parquet", "test_yaml": out / "test.yaml", "kit": kit_dir}
    write_table(_labels_table(observed, table), paths["labels"], LABELS)
    calibrations = []
    for cam in cameras:
        calibrations.append(out / f"{cam.name}.json")
        write_json(calibrations[-1], {"camera": cam.name, "width": cam.width, "height": cam.height,
                                      "K": cam.K.tolist(), "dist": cam.dist.tolist()})  # fmt: skip
    names = [cam.name for cam in cameras]
    paths["test_yaml"].write_text(yaml.safe_dump({"name": "synthetic", "fps": FPS, "cameras": names}))
    cell_cfg = {**CONFIG["cell"], "wavelength_nm": WAVELENGTH_NM}
    for name in ("cell", "cell_points", "air_residuals", "cameras", "points", "observations", "quality",
                 "residuals"):  # fmt: skip
        paths[name] = out / f"{name}.{'json' if name in ('cell', 'cameras', 'quality') else 'parquet'}"
    paths["picture"] = out / "reconstruction.png"
    run_reconstruct_cell(
        calibrations=calibrations, labels=paths["labels"], kit=kit_dir,
        cell=paths["cell"], points=paths["cell_points"], residuals=paths["air_residuals"],
        reconstruction_cfg=CONFIG["reconstruction"], cell_cfg=cell_cfg,
    )  # fmt: skip
    traced = ("cell", "cell_points", "air_residuals", "labels", "kit", "test_yaml", "cameras", "points",
              "observations", "quality", "residuals", "picture")  # fmt: skip
    run_trace_specimen(
        **{k: paths[k] for k in traced}, reconstruction_cfg=CONFIG["reconstruction"], cell_cfg=cell_cfg
    )
    return {**paths, "truth": truth, "observed": observed, "design": design}


def test_reconstruct_cell_writes_every_camera_and_the_fitted_cell(first_frame):
    cell = read_json(first_frame["cell"], "cell.json")
    assert sorted(cell["cameras"]) == [f"cam{i:02d}" for i in range(1, 14)] and cell["cameras_dropped"] == {}
    kit_radius = first_frame["design"].cell.outer_radius
    assert cell["cell"]["source"] and abs(cell["cell"]["outer_radius_mm"] - kit_radius) < 0.1
    points = read_table(first_frame["cell_points"], POINTS)
    assert set(points["frame"]) == {0} and len(points) > 100


def test_trace_specimen_records_the_cell_of_cell_json_in_quality_json(first_frame):
    """The first frame's quality.json: the reconstruction's cell with what reconstruct_cell's
    cell.json says of it and of the cameras, and the indices' wavelength (config) and
    temperature (kit)."""
    cell_doc = read_json(first_frame["cell"], "cell.json")
    quality = read_json(first_frame["quality"], "quality.json")
    for key in ("axis_tilt_deg", "cylinder_rms_mm", "source"):
        assert quality["cell"][key] == cell_doc["cell"][key], key
    assert quality["cell"]["wavelength_nm"] == WAVELENGTH_NM
    assert quality["cell"]["temperature_c"] == first_frame["design"].cell.temperature_c
    assert quality["cell"]["outer_radius_mm"] == cell_doc["cell"]["outer_radius_mm"]  # not refined
    assert quality["cameras_posed"] == cell_doc["cameras_posed"] and quality["cameras_dropped"] == {}
    assert list(quality)[-2:] == ["cameras_posed", "cameras_dropped"]
    assert quality["mean_reprojection_px"] < 0.1  # 0.05 px of noise per coordinate


def test_trace_specimen_writes_the_cell_frame_points_cameras_and_picture(first_frame, table):
    points = read_table(first_frame["points"], POINTS).set_index("id")
    truth = first_frame["truth"].set_index("id")
    membrane = table.loc[table["surface"] == "membrane", "id"]
    got = membrane[membrane.isin(points.index)]
    assert len(got) > 0.9 * len(membrane)
    err = np.linalg.norm(points.loc[got, ["x_mm", "y_mm", "z_mm"]].to_numpy()
                         - truth.loc[got, ["x_mm", "y_mm", "z_mm"]].to_numpy(), axis=1)  # fmt: skip
    assert np.sqrt((err**2).mean()) < 0.05  # mm, in the cell frame fixed by the bottom pedestal
    assert (points["time_s"] == REFERENCE_FRAME / FPS).all()
    cameras = read_cameras(first_frame["cameras"])
    assert list(cameras) == sorted(cameras) and len(cameras) == 13
    observations = read_table(first_frame["observations"], OBSERVATIONS)
    assert set(observations["frame"]) == {REFERENCE_FRAME} and len(observations) > 13 * 100
    assert first_frame["picture"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------- the timesteps from files


def _tracks(observed: pd.DataFrame, frames: list[int]) -> pd.DataFrame:
    """``TRACKS`` rows of a specimen at rest: the first frame's observations at every frame."""
    return pd.concat([observed.assign(frame=f) for f in frames], ignore_index=True).assign(
        area_px=20.0, sigma_px=0.05, reason=""
    )


@pytest.fixture(scope="module")
def timesteps(first_frame, table, tmp_path_factory) -> dict:
    """Two chunks of the specimen at rest (frames 0-1 and 2-3, frame 2 handed over), one camera
    knocked by ``KNOCK_PX`` at frame 3: run_triangulate_chunk per chunk, then
    run_collect_timesteps over both."""
    out = tmp_path_factory.mktemp("timesteps")
    observed, f = first_frame["observed"], first_frame
    wall_ids = table.loc[table["surface"] == "cell_outer", "id"]
    chunks = [_tracks(observed, [0, 1]), _tracks(observed, [2, 3])]
    knocked = (chunks[1]["camera"] == "cam03") & (chunks[1]["frame"] == 3) & chunks[1]["id"].isin(wall_ids)
    chunks[1].loc[knocked, "u_px"] += KNOCK_PX
    handover = _tracks(observed, [2])
    paths: dict = {"handover": out / "0000_handover.parquet", "last": out / "0001_handover.parquet"}
    write_table(handover, paths["handover"], TRACKS)
    write_table(handover.iloc[:0], paths["last"], TRACKS)
    for i, tracks in enumerate(chunks):
        stem = out / f"{i:04d}"
        write_table(tracks, f"{stem}_tracks.parquet", TRACKS)
        run_triangulate_chunk(
            tracks=[f"{stem}_tracks.parquet"], lags=[], cameras=f["cameras"], reference=f["quality"],
            reference_points=f["points"], kit=f["kit"], test_yaml=f["test_yaml"],
            points=f"{stem}.parquet", residuals=f"{stem}_residuals.parquet", motion=f"{stem}_motion.parquet",
            reconstruction_cfg=CONFIG["reconstruction"], tracking_cfg=CONFIG["tracking"],
        )  # fmt: skip
    labels = out / "labels.parquet"
    write_table(_labels_table(pd.concat([observed, observed.assign(frame=2)]), table), labels, LABELS)
    stems = [out / "0000", out / "0001"]
    for name in ("points", "observations", "tracking", "quality"):
        paths[name] = out / f"{name}.{'json' if name == 'quality' else 'parquet'}"
    run_collect_timesteps(
        chunk_points=[f"{s}.parquet" for s in stems],
        chunk_residuals=[f"{s}_residuals.parquet" for s in stems],
        chunk_motion=[f"{s}_motion.parquet" for s in stems], tracks=[f"{s}_tracks.parquet" for s in stems],
        handovers=[paths["handover"], paths["last"]], labels=labels, reference=f["quality"], kit=f["kit"],
        points=paths["points"], observations=paths["observations"], tracking=paths["tracking"],
        quality=paths["quality"], handover_px=CONFIG["tracking"]["handover_px"],
        cameras_left_out={"cam14": "video not found"},
    )  # fmt: skip
    return {**paths, "chunks": stems}


def test_triangulate_chunk_finds_the_first_frame_points_again(first_frame, timesteps, table):
    """The specimen at rest, seen as at the first frame: every frame's points are the first
    frame's (the cameras of cameras.json, the cell of quality.json, the fps of test.yaml)."""
    reference = read_table(first_frame["points"], POINTS).set_index("id")
    water = reference.index.difference(table.loc[table["surface"] == "cell_outer", "id"])
    points = read_table(f"{timesteps['chunks'][0]}.parquet", POINTS)
    assert sorted(points["frame"].unique()) == [0, 1]
    assert np.allclose(points.loc[points["frame"] == 1, "time_s"], 1 / FPS)
    for _, at in points.groupby("frame"):
        at = at.set_index("id")
        assert at.index.isin(water).all() and len(at) > 0.98 * len(water)
        d = at[["x_mm", "y_mm", "z_mm"]] - reference.loc[at.index, ["x_mm", "y_mm", "z_mm"]]
        assert np.abs(d.to_numpy()).max() < 0.01  # mm


def test_triangulate_chunk_finds_the_knocked_camera(timesteps):
    motion = read_table(f"{timesteps['chunks'][1]}_motion.parquet", MOTION).set_index(["camera", "frame"])
    assert motion.loc[("cam03", 3), "moved"] and motion.loc[("cam03", 3), "drift_px"] > KNOCK_PX / 2
    assert motion.drop(("cam03", 3))["moved"].sum() == 0
    assert motion.drop(("cam03", 3))["drift_px"].max() < 0.3


def test_collect_timesteps_joins_the_chunks_and_reports_the_test(first_frame, timesteps):
    points = read_table(timesteps["points"], POINTS)
    assert sorted(points["frame"].unique()) == [0, 1, 2, 3]
    tracking = read_table(timesteps["tracking"], TRACKS)
    observations = pd.read_parquet(timesteps["observations"])
    assert len(observations) == (tracking["reason"] == "").sum()
    quality = read_json(timesteps["quality"], "quality.json")
    reference = read_json(first_frame["quality"], "quality.json")
    assert quality["cell"] == reference["cell"]
    assert quality["reference_frame"]["frames"] == reference["frames"]
    assert quality["cameras_left_out"] == {"cam14": "video not found"}
    assert quality["handovers"]["checked"] == 13 and quality["handovers"]["disagreements"] == 0
    assert list(quality["camera_motion"]["moved"]) == ["cam03"]
    assert [f["frame"] for f in quality["frames"]] == [0, 1, 2, 3]


# ---------------------------------------------------------------- identify and track from files


def test_identify_then_track_one_camera_of_a_simulated_test(small_test, tmp_path, capsys):
    """Frame map, labels of chunk 0 (frames 0-1) and its tracks, the handover frame apart."""
    camera = "cam02"
    truth = read_cameras(small_test / "truth" / "cameras.json")[camera]
    calibration = tmp_path / "calibration.json"
    write_json(calibration, {"camera": camera, "width": truth.width, "height": truth.height,
                             "K": truth.K.tolist(), "dist": truth.dist.tolist()})  # fmt: skip
    video, test_yaml = small_test / "videos" / f"{camera}.mp4", small_test / "test.yaml"
    frames = tmp_path / "frames.parquet"
    run_frame_map(camera=camera, video=video, test_yaml=test_yaml, frame_count_video=[], frames=frames)
    chunk = {"start": 0, "stop": 2}
    labels = tmp_path / "labels.parquet"
    run_identify_targets(
        video=video, frames=frames, calibration=calibration, kit=small_test / "kit",
        labels=labels, frame=tmp_path / "frame.png", overlay=tmp_path / "overlay.png", chunk=chunk,
    )  # fmt: skip
    labelled = read_table(labels, LABELS)
    assert set(labelled["frame"]) == {0} and set(labelled["camera"]) == {camera}
    assert (labelled["id"] > 0).sum() > 100
    assert (tmp_path / "overlay.png").stat().st_size > 0
    tracks, handover = tmp_path / "tracks.parquet", tmp_path / "handover.parquet"
    run_track_targets(
        camera=camera, video=video, frames=frames, labels=labels, test_yaml=test_yaml, kit=small_test / "kit",
        tracks=tracks, handover=handover, chunk=chunk, tracking_cfg=CONFIG["tracking"],
    )  # fmt: skip
    tracked, shared = read_table(tracks, TRACKS), read_table(handover, TRACKS)
    assert sorted(tracked["frame"].unique()) == [0, 1] and set(shared["frame"]) == {2}
    reported = tracked[tracked["reason"] == ""].groupby("frame").size() / (labelled["id"] > 0).sum()
    assert reported[0] > 0.95 and reported[1] > 0.7  # 8 % axial strain over the test's 4 frames
    out = capsys.readouterr().out
    assert f"{camera}: every frame decoded for 3 reported of frames 0..2" in out
    fmap = read_table(frames, FRAME_MAP)
    write_table(fmap.assign(missing=True, video_index=-1, reason="dropped"), frames, FRAME_MAP)
    none = r"cam02\.mp4: camera cam02 recorded none of test frames 0\.\.1 \(see "
    with pytest.raises(ValueError, match=none):
        run_identify_targets(
            video=video, frames=frames, calibration=calibration, kit=small_test / "kit",
            labels=labels, frame=tmp_path / "f.png", overlay=tmp_path / "o.png", chunk=chunk,
        )  # fmt: skip
    assert len(read_table(labels, LABELS)) == 0  # written, empty, before the error
