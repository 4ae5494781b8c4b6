"""Shared parse-time logic: config validation, the tests, cameras, chunks, input functions.

Everything a rule needs that depends on wildcards is a `get_*` function here, so rules stay
declarative (no lambdas). Paths are relative to the working directory (the repository root);
every file's path pattern is triaxtrack.layout's, under results/{test} (`R`) or a test folder.
"""

import math
import os
import re
from functools import cache
from pathlib import Path

import yaml
from snakemake.exceptions import WorkflowError
from snakemake.logging import logger
from snakemake.utils import validate

from triaxtrack.errors import schema_problems, source_of
from triaxtrack.layout import CSV_TABLES, RESULTS, TEST_FOLDER
from triaxtrack.testfolder import TEST_YAML, TestFolder, TestFolderError

CONFIG_SCHEMA_PATH = workflow.source_path("../schemas/config.schema.yaml")
TEST_SCHEMA_PATH = workflow.source_path("../schemas/test.schema.yaml")
KIT_DIR = "results/kit"
# every file of results/<test>/ (R.points, ...; R.simulated: a simulated test's test folder)
R = RESULTS.under("results/{test}")
# simulated cameras are cam01..camNN (the schema caps NN at 32)
CAMERA_NAME_DIGITS = 2
# chunk ids are 0000, 0001, ...: keep in step with the `chunk` wildcard constraint
CHUNK_ID_DIGITS = 4


wildcard_constraints:
    test=r"[A-Za-z0-9_.-]+",
    camera=r"[A-Za-z0-9_.-]+",
    chunk=r"\d{4}",
    segment=r"\d{4}",


# ---------------------------------------------------------------- validation


def _load_schema(path):
    with open(path) as f:
        return yaml.safe_load(f)


def _config_sources():
    """(file name, its document) of every source of `config`, lowest precedence first: the
    workflow's configfile, each --configfile, then --config (named "--config")."""
    settings = getattr(workflow, "config_settings", None)
    cli = [Path(p).absolute() for p in getattr(settings, "configfiles", [])]
    own = [Path(p) for p in workflow.configfiles if Path(p).absolute() not in cli]
    sources = []
    for path in own + cli:
        relative = os.path.relpath(path)
        name = path if relative.startswith("..") else relative
        try:
            sources.append((str(name), _load_schema(path) or {}))
        except (OSError, yaml.YAMLError):
            sources.append((str(name), {}))
    if getattr(settings, "config", None):
        sources.append(("--config", dict(settings.config)))
    return sources or [("config", config)]


def _validate_config():
    """validate(config) (which also writes the schema's defaults into it), but a problem is
    reported in words: the file, the key, "did you mean" for a near miss; never the schema.
    """
    try:
        validate(config, "../schemas/config.schema.yaml")
    except WorkflowError:
        problems = schema_problems(
            config, _load_schema(CONFIG_SCHEMA_PATH), _config_sources()
        )
        if not problems:
            raise
        raise WorkflowError(
            "the configuration is not valid (every key is described in config/README.md):\n  "
            + "\n  ".join(problems)
        ) from None


_validate_config()


# ---------------------------------------------------------------- recorded test folders


def load_test_yaml(folder):
    """Read and validate FOLDER/test.yaml (triaxtrack.testfolder.TestFolder); return it with
    `cameras` as a list of mappings (`{"name": ...}` plus the optional per-camera keys) and
    `kit` defaulted to "kit". Raises WorkflowError naming the file, the key and a near miss on
    any problem; warns about top-level keys the workflow does not read (allowed: a recorder
    may write more)."""
    schema = _load_schema(TEST_SCHEMA_PATH)
    try:
        test = TestFolder.load(folder, schema)
    except TestFolderError as exc:
        _warn_unknown_keys(Path(folder) / TEST_YAML, exc.unknown_keys, schema)
        raise WorkflowError(str(exc)) from None
    _warn_unknown_keys(test.test_yaml, test.unknown_keys, schema)
    return test.doc


def _warn_unknown_keys(path, unknown, schema):
    if unknown:
        logger.warning(
            f"{path}: unknown top-level key(s) {', '.join(unknown)}: not read by the "
            f"workflow, which reads {', '.join(sorted(schema['properties']))}"
        )


# ---------------------------------------------------------------- the tests


def _collect_tests():
    """name -> spec. A spec has either `simulate` (overrides of config["simulation"]) or
    `path` (a recorded test folder) and `recorded` (its validated test.yaml).
    `--config test=PATH` replaces the `tests` list by that one recorded folder, and
    `--config tests_dir=DIR` by every folder in DIR that holds a test.yaml (an archive).
    """
    if config.get("test"):
        entries = [{"path": config["test"]}]
    elif config.get("tests_dir"):
        entries = [{"path": str(p.parent)} for p in _archive_tests(config["tests_dir"])]
    else:
        entries = config["tests"]
    tests = {}
    for entry in entries:
        if "simulate" in entry:
            name = entry["name"]
            spec = {"simulate": dict(entry["simulate"])}
        else:
            folder = os.path.normpath(entry["path"])
            recorded = load_test_yaml(folder)
            name = entry.get("name", recorded["name"])
            spec = {"path": folder, "recorded": recorded}
        if name in tests:
            where = source_of(["tests"], _config_sources())
            raise WorkflowError(
                f"{where}: `tests`: test name {name!r} is used more than once"
            )
        tests[name] = spec
    return tests


def _archive_tests(folder):
    """The test.yaml of every test folder directly in FOLDER, in name order."""
    root = Path(folder)
    if not root.is_dir():
        raise WorkflowError(f"tests_dir {folder}: not a folder")
    found = sorted(root.glob("*/test.yaml"))
    if not found:
        raise WorkflowError(
            f"tests_dir {folder}: no test folder (a folder with a test.yaml) in it"
        )
    return found


TESTS = _collect_tests()
SIMULATED = [name for name, spec in TESTS.items() if "simulate" in spec]
RECORDED = [name for name, spec in TESTS.items() if "path" in spec]


def _one_of(names):
    """A wildcard regex matching exactly these names (none: a regex that never matches)."""
    return "|".join(re.escape(name) for name in names) or "(?!)"


# Constraints of the `test` wildcard, set per rule, so that the simulation rules only match
# simulated tests and the inventory rules only recorded ones. Without them, a recorded test whose
# folder is a simulated one (`--config test=results/demo/simulated`) would make Snakemake
# ask the simulation rules (and their input functions) about its files.
SIMULATED_TEST = _one_of(SIMULATED)
RECORDED_TEST = _one_of(RECORDED)


def _spec(test):
    try:
        return TESTS[test]
    except KeyError:
        raise WorkflowError(
            f"unknown test {test!r}; configured: {sorted(TESTS)}"
        ) from None


def _sim_config(test):
    spec = _spec(test)
    if "simulate" not in spec:
        raise WorkflowError(f"test {test!r} is a recorded test, not a simulated one")
    return {**config["simulation"], **spec["simulate"]}


def get_load_frame_settings(wildcards):
    """The simulated load-frame log's settings of a simulated test (`load_frame`)."""
    return _sim_config(wildcards.test).get("load_frame", {})


def get_sim_config(wildcards):
    """Simulation settings of a simulated test: config["simulation"] with the test's
    `simulate` overrides applied key by key (fields of triaxtrack.simulate.SimulationConfig).
    """
    return _sim_config(wildcards.test)


def get_test_dir(test):
    """The test folder (test-folder.md): results/<test>/simulated for simulated tests, the
    configured folder for recorded ones."""
    spec = _spec(test)
    if "simulate" in spec:
        return R.simulated.root.format(test=test)
    return spec["path"]


def _test_file(test, pattern, **wildcards):
    """A file of the test folder: a pattern of triaxtrack.layout.TEST_FOLDER, filled."""
    return str(Path(get_test_dir(test)) / pattern.format(**wildcards))


def get_cameras(test):
    """Camera names: cam01..camNN for simulated tests; for recorded ones test.yaml's order,
    less the cameras left out (get_cameras_left_out)."""
    spec = _spec(test)
    if "simulate" in spec:
        n = _sim_config(test)["cameras"]
        return [f"cam{i:0{CAMERA_NAME_DIGITS}d}" for i in range(1, n + 1)]
    return _recorded_cameras(test)[0]


def get_cameras_left_out(wildcards):
    """{camera: why} of the cameras of a recorded test whose video cannot be read (missing,
    empty, unreadable, another frame rate), left out with `on_bad_camera: skip`; {} for
    simulated tests."""
    if "simulate" in _spec(wildcards.test):
        return {}
    return _recorded_cameras(wildcards.test)[1]


@cache
def _recorded_cameras(test):
    """(cameras kept, {left out: why}) of a recorded test, its videos (and their frame rates
    against test.yaml's) checked at parse time (triaxtrack.inventory.usable_cameras); a
    WorkflowError with `on_bad_camera: fail` or fewer
    than `min_cameras` kept."""
    from triaxtrack.inventory import usable_cameras

    names = [c["name"] for c in _spec(test)["recorded"]["cameras"]]
    videos = {name: _recorded_video(test, name) for name in names}
    try:
        kept, left_out = usable_cameras(
            videos,
            config["on_bad_camera"],
            config["min_cameras"],
            f"test {test!r}",
            _spec(test)["recorded"].get("fps"),
        )
    except ValueError as exc:
        raise WorkflowError(str(exc)) from None
    for camera, why in left_out.items():
        logger.warning(
            f"test {test!r}: camera {camera} left out (on_bad_camera: skip): {why}"
        )
    return kept, left_out


@cache
def get_frames(test):
    """Frames per video: from the simulation settings, from test.yaml `frames`, or else by
    probing the first camera's video (at parse time, once per test)."""
    spec = _spec(test)
    if "simulate" in spec:
        return _sim_config(test)["frames"]
    if "frames" in spec["recorded"]:
        return spec["recorded"]["frames"]
    from triaxtrack.video import probe_video

    # the index only: demuxing a whole video on every parse would slow every dry run (the
    # probe_video and frame_map jobs check each video against its index)
    video = _recorded_video(test, get_cameras(test)[0])
    return int(probe_video(video, index_only=True)["frames"])


def get_chunks(test):
    """Chunk ids "0000", "0001", ... covering the frames in blocks of config["chunk_size"]."""
    n = math.ceil(get_frames(test) / config["chunk_size"])
    if n > 10**CHUNK_ID_DIGITS:
        raise WorkflowError(f"test {test!r}: {n} chunks; raise chunk_size")
    return [f"{i:0{CHUNK_ID_DIGITS}d}" for i in range(n)]


def get_chunk_frames(wildcards):
    """Frame range of one chunk: dict(start=..., stop=...), stop exclusive."""
    if wildcards.chunk not in get_chunks(wildcards.test):
        raise WorkflowError(f"test {wildcards.test!r} has no chunk {wildcards.chunk}")
    size = config["chunk_size"]
    start = int(wildcards.chunk) * size
    return {"start": start, "stop": min(start + size, get_frames(wildcards.test))}


# ---------------------------------------------------------------- input functions: simulation


def _render_segments(test):
    """(start, stop) test frames of each video segment of a simulated test: chunk_size
    rounded up to whole GOPs, starting on the recorder's keyframe grid (render_segments).
    """
    from triaxtrack.simulate import SimulationConfig, gop_frames, render_segments

    gop = gop_frames(SimulationConfig.from_dict(_sim_config(test)))
    return render_segments(get_frames(test), config["chunk_size"], gop)


def get_segments(test):
    """Video segment ids "0000", "0001", ... of a simulated test (rule render_video_chunk)."""
    return [f"{i:0{CHUNK_ID_DIGITS}d}" for i in range(len(_render_segments(test)))]


def get_segment_frames(wildcards):
    """Frame range of one video segment: dict(start=..., stop=...), stop exclusive."""
    segments = _render_segments(wildcards.test)
    i = int(wildcards.segment)
    if i >= len(segments):
        raise WorkflowError(
            f"test {wildcards.test!r} has no video segment {wildcards.segment}"
        )
    start, stop = segments[i]
    return {"start": start, "stop": stop}


def get_camera_chunk_videos(wildcards):
    """All video segments of one simulated camera, in frame order."""
    return expand(
        R.sim_chunk_video,
        test=wildcards.test,
        camera=wildcards.camera,
        segment=get_segments(wildcards.test),
    )


def get_chunk_observations(wildcards):
    """Truth observations of every video segment of every camera of a simulated test."""
    return expand(
        R.sim_chunk_observations,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
        segment=get_segments(wildcards.test),
    )


def get_sim_videos(wildcards):
    """The joined video of every camera of a simulated test."""
    return expand(
        R.simulated.video,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
    )


def get_sim_calibrations(wildcards):
    """The calibration image folder of every camera of a simulated test."""
    return expand(
        R.simulated.calibration_images,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
    )


def get_sim_board_poses(wildcards):
    """The true calibration-board poses of every camera of a simulated test."""
    return expand(
        R.simulated.truth.board_poses,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
    )


# ---------------------------------------------------------------- input functions: recorded


def _recorded_video(test, camera):
    return _test_file(test, TEST_FOLDER.video, camera=camera)


def get_recorded_video(wildcards):
    """TEST_DIR/videos/<camera>.mp4 of a recorded test."""
    return _recorded_video(wildcards.test, wildcards.camera)


def get_recorded_test_yaml(wildcards):
    """TEST_DIR/test.yaml of a recorded test."""
    return _test_file(wildcards.test, TEST_FOLDER.test_yaml)


def get_recorded_spec(wildcards):
    """The validated test.yaml of a recorded test (cameras as mappings), with only the cameras
    measured (get_cameras: those left out are not)."""
    spec = _spec(wildcards.test)
    if "recorded" not in spec:
        raise WorkflowError(f"test {wildcards.test!r} is simulated, not recorded")
    kept = set(get_cameras(wildcards.test))
    cameras = [c for c in spec["recorded"]["cameras"] if c["name"] in kept]
    return {**spec["recorded"], "cameras": cameras}


def get_videos_checked(wildcards):
    """A recorded test's inventory (every video probed packet by packet, sizes and frame rates
    compared): the calibration and the frame maps wait for it, so that a cut or mismatched
    video stops the test, naming the file, before any heavy job runs; none for a simulated
    test."""
    if "recorded" in _spec(wildcards.test):
        return R.inventory.format(test=wildcards.test)
    return []


def get_inventory_probes(wildcards):
    """The probe of every camera's video of a recorded test, in test.yaml's camera order."""
    return expand(
        R.probe,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
    )


# ---------------------------------------------------------------- input functions: any test


def _check_camera(wildcards):
    if wildcards.camera not in get_cameras(wildcards.test):
        raise WorkflowError(
            f"test {wildcards.test!r} has no camera {wildcards.camera!r}; "
            f"cameras: {get_cameras(wildcards.test)}"
        )


def get_test_yaml(wildcards):
    """TEST_DIR/test.yaml of any test (simulated: written by simulate_scene)."""
    return _test_file(wildcards.test, TEST_FOLDER.test_yaml)


def get_test_kit(wildcards):
    """The kit folder of any test: the simulated test's kit/, or test.yaml's `kit`."""
    spec = _spec(wildcards.test)
    if "simulate" in spec:
        return _test_file(wildcards.test, TEST_FOLDER.kit)
    return str(Path(get_test_dir(wildcards.test)) / spec["recorded"]["kit"])


def get_calibration_folder(wildcards):
    """TEST_DIR/calibration/<camera>: the camera's board images."""
    _check_camera(wildcards)
    return _test_file(
        wildcards.test, TEST_FOLDER.calibration_images, camera=wildcards.camera
    )


def get_calibration_images(wildcards):
    """The camera's board images: the folder rendered by render_calibration (simulated), or
    the *.png files in it (recorded; none if it is missing: calibrate_camera then says so).
    """
    folder = get_calibration_folder(wildcards)
    if "simulate" in _spec(wildcards.test):
        return folder
    return sorted(str(p) for p in Path(folder).glob("*.png"))


def get_camera_video(wildcards):
    """TEST_DIR/videos/<camera>.mp4 of any test."""
    _check_camera(wildcards)
    return _recorded_video(wildcards.test, wildcards.camera)


def get_frame_count_video(wildcards):
    """The video whose frame count is the test's when test.yaml gives no `frames` (a recorded
    test: its first camera's, as get_frames); none otherwise. Read when the job runs, so that a
    dry run needs no readable video."""
    spec = _spec(wildcards.test)
    if "recorded" in spec and "frames" not in spec["recorded"]:
        return _recorded_video(wildcards.test, get_cameras(wildcards.test)[0])
    return []


# ---------------------------------------------------------------- targets


def get_calibrations(wildcards):
    """The calibration result of every camera of a test."""
    return expand(
        R.calibration,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
    )


def get_chunk_labels(wildcards):
    """The identification tables of every camera and chunk of a test."""
    return expand(
        R.chunk_labels,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
        chunk=get_chunks(wildcards.test),
    )


def _chunk_files(wildcards, pattern):
    return expand(
        pattern,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
        chunk=get_chunks(wildcards.test),
    )


def get_chunk_tracks(wildcards):
    """The tracks of every camera through one chunk."""
    return expand(
        R.tracks,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
        chunk=wildcards.chunk,
    )


def get_all_tracks(wildcards):
    """The tracks of every camera and chunk of a test."""
    return _chunk_files(wildcards, R.tracks)


def get_camera_tracks(wildcards):
    """One camera's tracks through every chunk, in frame order."""
    return expand(
        R.tracks,
        test=wildcards.test,
        camera=wildcards.camera,
        chunk=get_chunks(wildcards.test),
    )


def get_codec_lags(wildcards):
    """Every camera's departures of its P frames from its keyframes (rule measure_codec_lag);
    none when the correction is off or in fast mode (no P frames decoded around keyframes).
    """
    tracking = config["tracking"]
    if not tracking["codec_lag"] or (
        tracking["step_s"] is not None and tracking["fast"]
    ):
        return []
    return expand(
        R.codec_lag,
        test=wildcards.test,
        camera=get_cameras(wildcards.test),
    )


def get_all_handovers(wildcards):
    """The targets every camera's chunk carried to the next chunk's first frame."""
    return _chunk_files(wildcards, R.handover)


def get_timestep_points(wildcards):
    """The points of every chunk's processed frames."""
    return expand(
        R.chunk_points,
        test=wildcards.test,
        chunk=get_chunks(wildcards.test),
    )


def get_timestep_residuals(wildcards):
    """The observations (used or not) of every chunk's processed frames."""
    return expand(
        R.chunk_residuals,
        test=wildcards.test,
        chunk=get_chunks(wildcards.test),
    )


def get_timestep_motion(wildcards):
    """The camera-motion check of every chunk."""
    return expand(
        R.chunk_motion,
        test=wildcards.test,
        chunk=get_chunks(wildcards.test),
    )


# ---------------------------------------------------------------- the load-frame log


def has_load_frame(test):
    """Whether a test has a load-frame log: a simulated test whose settings have `load_frame`,
    a recorded one whose test.yaml has a `load_frame` entry."""
    spec = _spec(test)
    if "simulate" in spec:
        return bool(_sim_config(test).get("load_frame"))
    return "load_frame" in spec["recorded"]


def get_load_frame_log(wildcards):
    """The load-frame log's file: TEST_DIR/loadframe.csv of a simulated test, test.yaml's
    `load_frame.file` of a recorded one."""
    test = wildcards.test
    if not has_load_frame(test):
        raise WorkflowError(
            f"test {test!r} has no load-frame log (test.yaml load_frame)"
        )
    spec = _spec(test)
    if "simulate" in spec:
        return _test_file(test, TEST_FOLDER.load_frame_log)
    return str(Path(get_test_dir(test)) / spec["recorded"]["load_frame"]["file"])


def get_final_outputs():
    """Everything the default target builds: the kit; per simulated test its test folder and
    simulation_check.json; per recorded test its inventory.json; per test and camera its
    calibration and frame map; per test the labels of every camera's chunk starts, the cameras
    and cell of the first frame (cameras.json and a picture), every processed frame's points,
    observations, tracks and quality.json, the volume and strains (and volume.csv), a few PLY
    meshes, the membrane's ParaView series, and the report's figures, movie and 3-D viewer; per
    test with a load-frame log its stress and strain (and stress_strain.csv), the clock report
    and the stress figures (simulated: the log and its truth).
    """
    outputs = [KIT_DIR]
    S = R.simulated
    for test in SIMULATED:
        outputs += expand(
            [
                S.test_yaml,
                S.kit,
                S.truth.cameras,
                S.truth.volume,
                S.truth.scene,
                S.truth.points,
                S.truth.observations,
                R.simulation_check,
            ],
            test=test,
        )
        outputs += expand(
            [S.video, S.calibration_images, S.truth.board_poses],
            test=test,
            camera=get_cameras(test),
        )
    for test in RECORDED:
        outputs += expand(R.inventory, test=test)
    for test in TESTS:
        outputs += expand(
            [R.calibration, R.frames], test=test, camera=get_cameras(test)
        )
        outputs += expand(
            [
                R.labels,
                R.cameras,
                R.points,
                R.observations,
                R.tracking,
                R.quality,
                R.volume,
                R.strains,
                R.mesh,
                R.volume_strain_figure,
                R.strain_maps_figure,
                R.reprojection_figure,
                R.tracking_figure,
                R.specimen_movie,
                R.specimen_player,
                R.reconstruction_picture,
                R.csv_of("volume"),
                R.paraview,
                R.viewer,
            ],
            test=test,
        )
        if has_load_frame(test):
            outputs += expand(
                [
                    R.stress_strain,
                    R.csv_of("stress_strain"),
                    R.clock,
                    R.q_strain_figure,
                    R.volumetric_strain_figure,
                    R.modulus_figure,
                ],
                test=test,
            )
        if test in SIMULATED and has_load_frame(test):
            outputs += expand(
                [S.load_frame_log, S.truth.load_frame, S.truth.stress_strain],
                test=test,
            )
    return outputs
