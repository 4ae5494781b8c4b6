"""Errors a user can act on: config and test.yaml problems name the file, the key and a near miss
(never the schema); unknown test.yaml keys are warned about; a failed job's reason reaches the
console (the Snakefile's `onerror`)."""

from __future__ import annotations

import copy

import yaml
from test_workflow import REPO, run_snakemake, workflow_copy

from triaxtrack.errors import (
    did_you_mean,
    failed_jobs,
    format_failed_jobs,
    job_log_reason,
    schema_problems,
    unknown_top_level_keys,
)

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
