"""Fast mode against every-frame tracking on one simulated test (issue 17's must-show).

    python bench/fast_mode.py EVERY FAST

``EVERY`` and ``FAST`` are two copies of a run's outputs, each a folder holding ``volume.parquet``
(``results/<test>/volume.parquet``) and ``track_targets/`` (``benchmarks/<test>/track_targets``),
e.g. for config/slow.yaml, run first with ``tracking: {step_s: 2, fast: false}`` and copied aside,
then again with ``fast: true``. Prints the sum and the largest of the tracking jobs' wall time
(Snakemake's benchmark column ``s``; on a loaded machine also their CPU time, ``cpu_time``) and
peak memory (``max_rss``) of each, their ratios, and the
largest difference of the two volume series at the frames both measured, in % of V0 (the volume
at the first frame), with the volumetric strains' largest difference.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.layout import RESULTS


def job_figures(folder: Path) -> tuple[float, float, float, float, int]:
    """Sum and largest ``s`` (seconds), sum of ``cpu_time`` (seconds), largest ``max_rss`` (MB)
    and the number of benchmark files under ``folder/track_targets``."""
    files = sorted((folder / "track_targets").rglob("*.tsv"))
    if not files:
        raise SystemExit(f"{folder}/track_targets: no benchmark files")
    tables = pd.concat([pd.read_csv(f, sep="\t") for f in files], ignore_index=True)
    rss = pd.to_numeric(tables["max_rss"], errors="coerce")
    cpu = float(pd.to_numeric(tables["cpu_time"], errors="coerce").sum())
    return float(tables["s"].sum()), float(tables["s"].max()), cpu, float(rss.max()), len(files)


def volume_difference(every: pd.DataFrame, fast: pd.DataFrame) -> tuple[float, float, int]:
    """Largest |V_fast - V_every| in % of every-frame's V0, the volumetric strains' largest
    difference, and the number of frames compared (those both report a volume at)."""
    both = every.merge(fast, on="frame", suffixes=("_every", "_fast")).dropna(
        subset=["volume_mm3_every", "volume_mm3_fast"]
    )
    v0 = float(every.sort_values("frame")["volume_mm3"].dropna().iloc[0])
    dv = np.abs(both["volume_mm3_fast"] - both["volume_mm3_every"]).max() / v0 * 100
    de = np.abs(both["volumetric_strain_fast"] - both["volumetric_strain_every"]).max()
    return float(dv), float(de), len(both)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("every", type=Path, help="outputs of the every-frame run")
    p.add_argument("fast", type=Path, help="outputs of the fast-mode run")
    args = p.parse_args(argv)
    jobs = {"every-frame mode": job_figures(args.every), "fast mode": job_figures(args.fast)}
    for name, (total, longest, cpu, rss, n) in jobs.items():
        print(f"track_targets, {name:>16}: {total:8.1f} s wall in {n} jobs (longest {longest:.1f} s), "
              f"{cpu:.1f} s CPU, peak {rss:.0f} MB")  # fmt: skip
    every, fast = jobs["every-frame mode"], jobs["fast mode"]
    print(f"fast / every-frame: {fast[0] / every[0]:.3f} of the tracking jobs' wall time (aim <= 0.25), "
          f"{fast[2] / every[2]:.3f} of their CPU time")  # fmt: skip
    dv, de, n = volume_difference(
        pd.read_parquet(args.every / RESULTS.volume), pd.read_parquet(args.fast / RESULTS.volume)
    )
    print(f"volume at the {n} frames both measured: largest difference {dv:.5f} % of V0 (aim <= 0.01 %); "
          f"volumetric strain {de:.2e}")  # fmt: skip


if __name__ == "__main__":
    main()
