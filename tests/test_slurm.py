"""The SLURM profile (profiles/slurm/config.yaml): shipped without placeholders, its groups
naming rules that exist, a dry run through it bundling the per-camera chunk jobs, and (marked
`slurm`, deselected by default) a real run through it on a tiny simulated test, when a SLURM
cluster answers `sinfo`:

    sudo .ci/slurm-single-node.sh && .venv/bin/pytest -m slurm
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess

import pytest
import yaml
from test_workflow import REPO, job_counts, run_snakemake, workflow_copy, write_yaml

PROFILE_DIR = REPO / "profiles" / "slurm"
PROFILE = PROFILE_DIR / "config.yaml"


def _profile() -> dict:
    return yaml.safe_load(PROFILE.read_text())


def _rule_names() -> set[str]:
    text = "".join(p.read_text() for p in (REPO / "workflow" / "rules").glob("*.smk"))
    return set(re.findall(r"^rule (\w+):", text, flags=re.MULTILINE))


def test_profile_has_no_placeholder_and_parses():
    """Nothing to edit before a first run: no CHANGE_ME, no partition (the cluster's default),
    job status by squeue (no accounting database needed)."""
    assert "CHANGE_ME" not in PROFILE.read_text()
    profile = _profile()
    assert isinstance(profile, dict) and profile["executor"] == "slurm"
    resources = profile.get("default-resources") or {}
    assert "slurm_partition" not in resources and "slurm_account" not in resources
    assert {"mem_mb", "runtime"} <= set(resources)
    assert profile["slurm-status-command"] == "squeue"


def test_profile_groups_name_workflow_rules():
    profile = _profile()
    groups, components = profile["groups"], profile["group-components"]
    assert set(groups) <= _rule_names(), set(groups) - _rule_names()
    assert {"identify_targets", "track_targets"} <= set(groups)
    assert set(components) == set(groups.values())
    assert all(isinstance(n, int) and n >= 1 for n in components.values())
    assert isinstance(profile["cores"], int) and profile["cores"] >= 1


def test_profile_dry_run_bundles_chunk_jobs():
    """A dry run through the profile (default config: 13 cameras x 2 chunks) shows each grouped
    rule's jobs bundled `group-components` at a time."""
    pytest.importorskip("snakemake_executor_plugin_slurm")
    proc = run_snakemake("-n", "--forceall", "--nolock", "--profile", str(PROFILE_DIR))
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    counts = job_counts(out)
    profile = _profile()
    for rule, group in profile["groups"].items():
        bundles = len(re.findall(rf"Group job {re.escape(group)} ", out))
        assert bundles == math.ceil(counts[rule] / profile["group-components"][group]), (rule, bundles)


def _slurm_answers() -> bool:
    if shutil.which("sinfo") is None or shutil.which("sbatch") is None:
        return False
    try:
        proc = subprocess.run(["sinfo", "-h", "-o", "%P %a"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return proc.returncode == 0 and " up" in proc.stdout


@pytest.mark.slurm
def test_profile_runs_a_tiny_test_on_slurm(tmp_path):
    """The shipped profile, unchanged, on a real SLURM cluster: a simulated test of 3 cameras x
    4 frames (chunks of 2), through calibration, identification and tracking. Every job is
    submitted with sbatch (the default partition, no account) and watched with squeue; the
    render, identify and track jobs go in bundles. A few minutes on a 2-CPU node."""
    if not _slurm_answers():
        pytest.skip("no SLURM cluster answers `sinfo` (sudo .ci/slurm-single-node.sh sets one up)")
    # tmp_path must be on a file system the nodes share: true on one node; on a cluster, run
    # pytest with --basetemp on a shared file system
    work = workflow_copy(tmp_path)
    test = "slurmtiny"
    config = write_yaml(
        work / "tiny.yaml",
        {"chunk_size": 2, "tests": [{"name": test, "simulate": {
            "cameras": 3, "frames": 4, "calibration_images": 8, "axial_strain": 0.01,
            "axial_nonuniformity": 0.03}}]},
    )  # fmt: skip
    cameras, chunks = ["cam01", "cam02", "cam03"], ["0000", "0001"]
    targets = [f"results/{test}/track/{c}/{k}.parquet" for c in cameras for k in chunks]
    proc = run_snakemake(
        "--profile", str(PROFILE_DIR), *targets, "--configfile", str(config), workdir=work, timeout=None
    )  # fmt: skip
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    for target in targets:
        assert (work / target).is_file(), target
    counts = job_counts(out)
    assert counts["identify_targets"] == counts["track_targets"] == 6
    assert counts["render_video_chunk"] == 3  # one segment a camera: the GOP grid (2 s) > 4 frames
    for group in ("render", "identify", "track"):
        assert f"Group job {group} " in out, group
    submitted = len(re.findall(r"has been submitted with SLURM jobid \d+", out))
    assert 0 < submitted < counts["total"], (submitted, counts["total"])
    assert "CHANGE_ME" not in out and "invalid partition" not in out
