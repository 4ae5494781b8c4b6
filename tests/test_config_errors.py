"""Errors a user can act on: config and test.yaml problems name the file, the key and a near miss
(never the schema); unknown test.yaml keys are warned about; the package's config sections
(``from_dict``) refuse unknown keys by one rule and take their defaults from the dataclasses; a
failed job's reason reaches the console (the Snakefile's `onerror`)."""

from __future__ import annotations

import copy
import re

import pytest
import yaml
from snakemake.utils import update_config
from test_workflow import REPO, run_snakemake, workflow_copy

from triaxtrack.calibrate import CalibrationConfig
from triaxtrack.config_section import field_names, section_dict
from triaxtrack.errors import (
    did_you_mean,
    failed_jobs,
    format_failed_jobs,
    job_log_reason,
    schema_problems,
    unknown_top_level_keys,
)
from triaxtrack.optics import CellConfig
from triaxtrack.reconstruction_config import SfmConfig, TriangulationConfig
from triaxtrack.report import ReportConfig
from triaxtrack.score import ScoreTolerances
from triaxtrack.simulate import SimulationConfig
from triaxtrack.simulate.loadlog import LoadFrameSimulation
from triaxtrack.stress import StressConfig
from triaxtrack.tracking_config import TrackingConfig
from triaxtrack.volume import VolumeConfig

CONFIG_SCHEMA = yaml.safe_load((REPO / "workflow" / "schemas" / "config.schema.yaml").read_text())
TEST_SCHEMA = yaml.safe_load((REPO / "workflow" / "schemas" / "test.schema.yaml").read_text())
DEFAULTS = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
SCHEMA_WORDS = ("additionalProperties", "$defs", "'properties'", "Failed validating")


def merged(**overrides) -> dict:
    config = copy.deepcopy(DEFAULTS)
    config.update(copy.deepcopy(overrides))
    return config


def test_did_you_mean_picks_the_near_miss():
    assert did_you_mean("chunksize", ["chunk_size", "tests", "test"]) == "; did you mean 'chunk_size'?"
    assert did_you_mean("frame", TEST_SCHEMA["properties"]) == "; did you mean 'frames'?"
    assert did_you_mean("h246", ["h264", "h265"]) == "; did you mean 'h264'?"  # anagram wins a tie
    assert did_you_mean("colour", ["chunk_size", "tests"]) == ""


def test_a_config_typo_names_the_file_the_key_and_the_key_meant():
    mine = {"chunksize": 25, "tests": [{"name": "x", "simulate": {"seeed": 2, "codec": "h246"}}]}
    config = merged(**mine)
    problems = schema_problems(config, CONFIG_SCHEMA, [("config/config.yaml", DEFAULTS), ("my.yaml", mine)])
    assert problems == [
        "my.yaml: `chunksize`: unknown key 'chunksize'; did you mean 'chunk_size'?",
        "my.yaml: `tests[0].simulate.codec`: 'h246' is not one of ['h264', 'h265']; did you mean 'h264'?",
        "my.yaml: `tests[0].simulate.seeed`: unknown key 'seeed'; did you mean 'seed'?",
    ]
    # a key set in the workflow's own file is blamed on it; a valid config has no problems
    defaults = [("config/config.yaml", DEFAULTS)]
    assert schema_problems(merged(chunk_size=1), CONFIG_SCHEMA, defaults) == [
        "config/config.yaml: `chunk_size`: 1 is less than the minimum of 2"
    ]
    assert schema_problems(DEFAULTS, CONFIG_SCHEMA, defaults) == []


def test_a_test_entry_with_both_or_neither_form_says_which_keys_it_needs():
    for entry, has in (({"name": "t", "simulate": {}, "path": "p"}, "`name`, `simulate`, `path`"),
                       ({"name": "t"}, "`name`")):  # fmt: skip
        problems = schema_problems(merged(tests=[entry]), CONFIG_SCHEMA, [("c.yaml", {"tests": [entry]})])
        assert problems == [
            "c.yaml: `tests[0]`: one test, either simulated (`simulate`) or recorded (`path`): "
            f"needs exactly one of `name` + `simulate` or `path`; it has {has}"
        ]


def test_long_values_are_shortened_and_the_schema_never_shown():
    value = {"model": list(range(200))}
    problems = schema_problems(merged(calibration=value), CONFIG_SCHEMA, [("c.yaml", DEFAULTS)])
    assert problems and all(len(line) < 250 for line in problems)
    assert not any(word in line for line in problems for word in SCHEMA_WORDS)


def test_test_yaml_problems_and_unknown_top_level_keys():
    doc = {"name": "t", "fps": 15, "frame": 6, "recorder": "NVR-16",
           "cameras": ["cam01", {"name": "cam02", "start_ofset_s": 0.2}]}  # fmt: skip
    assert unknown_top_level_keys(doc, TEST_SCHEMA) == ["'frame' (did you mean 'frames'?)", "'recorder'"]
    assert schema_problems(doc, TEST_SCHEMA, [("t.yaml", doc)]) == [
        "t.yaml: `cameras[1].start_ofset_s`: unknown key 'start_ofset_s'; did you mean 'start_offset_s'?"
    ]
    assert schema_problems({"name": "t", "cameras": ["a"]}, TEST_SCHEMA, [("t.yaml", {})]) == [
        "t.yaml: the top level: 'fps' is a required property"
    ]


# ---------------------------------------------------------------- config sections -> dataclasses

#: Each config section the package reads (every one but the top-level keys and ``tests``), and
#: the dataclasses it feeds (``simulation`` is also each simulated test's ``simulate``, on top of it).
SECTIONS = {
    "calibration": (CalibrationConfig,),
    "reconstruction": (SfmConfig, TriangulationConfig),
    "cell": (CellConfig,),
    "tracking": (TrackingConfig,),
    "volume": (VolumeConfig,),
    "stress": (StressConfig,),
    "report": (ReportConfig,),
    "score": (ScoreTolerances,),
    "simulation": (SimulationConfig,),
    "simulation.load_frame": (LoadFrameSimulation,),
}
#: dataclass fields the config does not expose (settable from Python only)
NOT_IN_CONFIG = {"tracking": {"ink_fraction"}}  # the detector's ink threshold (DetectParams)
BUILDERS = [(section, cls) for section, classes in SECTIONS.items() for cls in classes]
IDS = [f"{section}-{cls.__name__}" for section, cls in BUILDERS]


def refused(message: str):
    """pytest.raises(ValueError) whose message starts with ``message`` (taken literally)."""
    return pytest.raises(ValueError, match=f"^{re.escape(message)}")


def schema_section(section: str) -> dict:
    """The schema of a config section (``simulation`` and its ``load_frame``: the definition
    shared with each test's ``simulate``)."""
    if section == "simulation":
        return CONFIG_SCHEMA["$defs"]["simulation"]
    if section == "simulation.load_frame":
        return CONFIG_SCHEMA["$defs"]["simulation"]["properties"]["load_frame"]
    return CONFIG_SCHEMA["properties"][section]


@pytest.mark.parametrize(("section", "cls"), BUILDERS, ids=IDS)
def test_an_unknown_key_in_a_section_is_an_error_naming_section_key_and_known_keys(section, cls):
    known = field_names(*SECTIONS[section]) + (("preset",) if cls is SimulationConfig else ())
    with pytest.raises(ValueError) as refusal:
        cls.from_dict({"colour": 1})
    assert str(refusal.value) == f"{section}: unknown key 'colour'; known keys: {', '.join(sorted(known))}"
    with refused(f"{section}: must be a mapping of settings, not 3"):
        cls.from_dict(3)


def test_a_near_miss_is_named_with_the_key_meant_and_every_unknown_key_is_listed():
    with refused("tracking: unknown keys 'gates' (did you mean 'gate'?), 'x'; known keys: codec_lag,"):
        TrackingConfig.from_dict({"gates": 0.2, "x": 1, "gate": 0.3})
    with refused("stress: unknown key 'search' (did you mean 'search_s'?)"):
        StressConfig.from_dict({"search": [0, 1]})
    with refused("score: unknown key 'volume_rels' (did you mean 'volume_rel'?)"):
        ScoreTolerances.from_dict({"volume_rels": 0.01})
    with refused("simulation.load_frame: unknown key 'rate' (did you mean 'rate_hz'?)"):
        LoadFrameSimulation.from_dict({"rate": 5.0})
    with refused("simulation: unknown key 'camera' (did you mean 'cameras'?)"):
        SimulationConfig.from_dict({"preset": "nvr", "camera": 4})


def test_the_reconstruction_section_feeds_sfm_and_triangulation_each_taking_its_own_keys():
    section = {"ransac_px": 3.0, "min_targets": 9, "min_rays": 3, "iterations": 5, "max_residual_px": 0.7}
    sfm, tri = SfmConfig.from_dict(section), TriangulationConfig.from_dict(section)
    assert (sfm.ransac_px, sfm.min_targets, sfm.max_residual_px) == (3.0, 9, 0.7)
    assert (tri.min_rays, tri.iterations, tri.max_residual_px) == (3, 5, 0.7)  # a shared key: both
    assert SfmConfig.from_dict({"refine_cell": True}) == SfmConfig()  # TriangulationConfig's key
    assert TriangulationConfig.from_dict({"pose_from_water": False}) == TriangulationConfig()  # SfmConfig's
    for cls in (SfmConfig, TriangulationConfig):  # a key neither reads is refused by both
        with refused("reconstruction: unknown key 'ransac' (did you mean 'ransac_px'?)"):
            cls.from_dict({**section, "ransac": 2.0})
    # the pipeline's use: every stage is handed the whole section of config/config.yaml
    assert SfmConfig.from_dict(DEFAULTS["reconstruction"]) == SfmConfig()
    assert TriangulationConfig.from_dict(DEFAULTS["reconstruction"]) == TriangulationConfig()


@pytest.mark.parametrize(("section", "cls"), BUILDERS, ids=IDS)
def test_the_defaults_are_the_dataclasses_and_config_yaml_writes_them_out(section, cls):
    """A key left out (or the whole section: None) takes the field's default; config.yaml's own
    values (every key written out for the reader) are those defaults, so the two cannot drift."""
    assert cls.from_dict({}) == cls() and cls.from_dict(None) == cls()
    top, _, sub = section.partition(".")
    written = DEFAULTS[top].get(sub, {}) if sub else DEFAULTS[top]
    assert cls.from_dict(written) == cls(), f"config/config.yaml `{section}`: not {cls.__name__}'s defaults"


def test_none_is_a_value_not_the_default():
    """null in a config file means "none" (or "the kit's") for fields whose default is None;
    it is passed as given, never replaced by a default, and valid configs write it nowhere else."""
    assert TrackingConfig.from_dict({"step_s": None}).step_s is None
    assert TrackingConfig.from_dict({"step_s": 2.0}).step_s == 2.0
    assert TrackingConfig.from_dict({"gate": None}).gate is None  # the workflow's schema refuses it first
    assert StressConfig.from_dict({"search_s": None, "zero_time_s": None}) == StressConfig()
    assert StressConfig.from_dict({"search_s": [-1, 2]}).search_s == (-1.0, 2.0)  # per-class casting kept
    assert ScoreTolerances.from_dict({"wrong_ids": 0}).wrong_ids == 0.0
    assert section_dict(None, "score", ["a"]) == {}


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_the_schema_and_the_dataclasses_know_the_same_keys(section):
    """The workflow validates config.yaml against the schema when it loads; the package's
    from_dict refuses what the dataclasses do not know: the two agree key for key."""
    schema = schema_section(section)
    assert schema.get("additionalProperties") is False, f"`{section}` takes any key in the schema"
    fields = set(field_names(*SECTIONS[section])) - NOT_IN_CONFIG.get(section, set())
    assert set(schema["properties"]) == fields


def test_every_section_of_the_config_is_read_through_dataclasses():
    """No section of config.yaml is read as a plain mapping: each (every mapping at the top level
    but ``tests``) has its dataclasses, with their one rule for keys and defaults."""
    sections = {key for key, value in CONFIG_SCHEMA["properties"].items()
                if value.get("type") == "object" or "$ref" in value}  # fmt: skip
    assert sections == {section for section in SECTIONS if "." not in section}


CONFIG_FILES = sorted(path.name for path in (REPO / "config").glob("*.yaml") if path.name != "kit.yaml")


@pytest.mark.parametrize("name", CONFIG_FILES)
def test_every_config_file_loads_through_the_schema_and_the_from_dicts(name):
    """Each config/*.yaml on top of config/config.yaml, merged as Snakemake merges a
    --configfile (mappings key by key): valid against the schema, and every section and every
    simulated test builds its dataclasses."""
    config = copy.deepcopy(DEFAULTS)
    own = yaml.safe_load((REPO / "config" / name).read_text()) or {}
    update_config(config, copy.deepcopy(own))
    sources = [("config/config.yaml", DEFAULTS), (f"config/{name}", own)]
    assert schema_problems(config, CONFIG_SCHEMA, sources) == []
    for section, classes in SECTIONS.items():
        if "." not in section:
            for cls in classes:
                cls.from_dict(config.get(section))
    for test in config["tests"]:
        if "simulate" in test:
            sim = SimulationConfig.from_dict({**config["simulation"], **test["simulate"]})
            LoadFrameSimulation.from_dict(sim.load_frame)


# ---------------------------------------------------------------- failed jobs

SNAKEMAKE_LOG = """\
[Wed Nov 25 03:12:01 2026]
localrule probe_video:
    input: /lab/t/videos/cam03.mp4
Error in rule probe_video:
    message: None
    jobid: 4
    input: /lab/t/videos/cam03.mp4
    output: results/t/inventory/cam03.json
    log: {log} (check log file(s) for error details)
Error in rule frame_map:
    message: None
    jobid: 7
    wildcards: test=t, camera=cam04
    log: {other}, {missing} (check log file(s) for error details)
Exiting because a job execution failed. Look above for error messages
"""

TRACEBACK = """\
[h264 @ 0x55] some FFmpeg chatter
Traceback (most recent call last):
  File "/x/.snakemake/scripts/tmpab.probe_video.py", line 12, in <module>
    probe = probe_video(snakemake.input.video)
            ^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^
av.error.InvalidDataError: [Errno 1094995529] Invalid data found when processing input

The above exception was the direct cause of the following exception:

Traceback (most recent call last):
  File "/x/.snakemake/scripts/tmpab.probe_video.py", line 12, in <module>
    probe = probe_video(snakemake.input.video)
ValueError: /lab/t/videos/cam03.mp4: the video file is empty (0 bytes)
second line of the message
"""


def test_the_reason_is_the_last_exception_of_a_job_log():
    assert job_log_reason(TRACEBACK) == (
        "ValueError: /lab/t/videos/cam03.mp4: the video file is empty (0 bytes)\nsecond line of the message"
    )
    shell_log = "step 1\nstep 2\nerror: calibration board not found in 3 of 8 images\n\n"
    assert job_log_reason(shell_log) == "step 1\nstep 2\nerror: calibration board not found in 3 of 8 images"
    long = "Traceback (most recent call last):\n  File x\nKeyError: 'a'\n" + "more\n" * 20
    assert job_log_reason(long, max_lines=4).splitlines()[-1] == "... (18 more lines in the log)"


def test_failed_jobs_are_read_from_snakemakes_log_and_printed_with_their_reason(tmp_path):
    log, other, missing = tmp_path / "probe.log", tmp_path / "frame_map.log", tmp_path / "gone.log"
    log.write_text(TRACEBACK)
    other.write_text("RuntimeError: frame map of cam04 does not fit its video\n")
    text = SNAKEMAKE_LOG.format(log=log, other=other, missing=missing)
    assert failed_jobs(text) == [
        {"rule": "probe_video", "wildcards": "", "logs": [str(log)]},
        {"rule": "frame_map", "wildcards": "test=t, camera=cam04", "logs": [str(other), str(missing)]},
    ]
    main_log = tmp_path / "run.snakemake.log"
    main_log.write_text(text)
    assert format_failed_jobs([str(main_log)]) == "\n".join([
        "triaxtrack: 2 job(s) failed; the reason at the end of each job's log:",
        f"  rule probe_video, {log}:",
        "    ValueError: /lab/t/videos/cam03.mp4: the video file is empty (0 bytes)",
        "    second line of the message",
        f"  rule frame_map (test=t, camera=cam04), {other}:",
        "    RuntimeError: frame map of cam04 does not fit its video",
        f"  rule frame_map (test=t, camera=cam04), {missing}:",
        "    (cannot read the log: No such file or directory)",
    ])  # fmt: skip
    assert format_failed_jobs(str(main_log)).startswith("triaxtrack: 2 job(s)")  # Snakemake 8: one path
    assert format_failed_jobs([str(tmp_path / "no.log")]) == ""


# ---------------------------------------------------------------- through Snakemake


def test_snakemake_names_the_config_file_and_the_key_without_the_schema(tmp_path):
    mine = tmp_path / "mine.yaml"
    mine.write_text("chunksize: 25\n")
    proc = run_snakemake("-n", "--nolock", "--configfile", str(mine), timeout=None)
    output = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert f"{mine}: `chunksize`: unknown key 'chunksize'; did you mean 'chunk_size'?" in output
    assert not any(word in output for word in SCHEMA_WORDS) and len(output.splitlines()) < 30, output
    proc = run_snakemake("-n", "--nolock", "--config", "chunk_size=1", timeout=None)
    assert "--config: `chunk_size`: 1 is less than the minimum of 2" in proc.stdout + proc.stderr


def test_a_failed_job_prints_its_reason_and_unknown_test_yaml_keys_are_warned_about(tmp_path):
    """A recorded test whose test.yaml has `frame: 6` (a typo of `frames`) and a video cut short
    behind a whole index (its index, read when the workflow loads, is intact): the warning names
    the key, and the probe job's failure reaches the console with its reason."""
    from test_probe_faults import cut, write_video

    folder = tmp_path / "lab-test"
    (folder / "videos").mkdir(parents=True)
    (folder / "kit").mkdir()
    video = folder / "videos" / "cam01.mp4"
    cut(write_video(tmp_path / "whole.mp4", faststart=True), video, 0.6)
    write_video(folder / "videos" / "cam02.mp4")
    (folder / "test.yaml").write_text(yaml.safe_dump({"name": "lab", "fps": 15, "frames": 6, "frame": 6,
                                                      "cameras": ["cam01", "cam02"]}))  # fmt: skip
    work = workflow_copy(tmp_path)
    proc = run_snakemake("--cores", "1", "--config", f"test={folder}", "--",
                         "results/lab/inventory/cam01.json", workdir=work, timeout=None)  # fmt: skip
    output = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert f"{folder / 'test.yaml'}: unknown top-level key(s) 'frame' (did you mean 'frames'?)" in output
    assert "triaxtrack: 1 job(s) failed; the reason at the end of each job's log:" in output, output
    assert "  rule probe_video, logs/lab/probe_video/cam01.log:\n" in output
    assert f"    ValueError: {video}: truncated video: its index lists" in output
