"""The continuity and precision figures of a simulated test's series (issue 16), against its truth.

    .venv/bin/python bench/series.py results/<test> [--plot out.png]

Prints, for ``results/<test>/volume.parquet`` against ``results/<test>/simulated/truth``:

* the volume-change error at frame 1 and its largest frame-to-frame step, where it is and
  whether that frame is a chunk's first frame or a keyframe (% of V0);
* the spread over frames (standard deviation) of the axial strain (global and local), of the
  volumetric strain, and their largest error against the truth's (dimensionless);
* the honesty of the uncertainties: the share of membrane points within 2 ``sigma_mm`` of truth
  and the RMS of error / ``sigma_mm`` (``sigma_mm`` the 3-D standard uncertainty), and the same
  for the volume with ``volume_sigma_mm3`` and for the axial strain with ``axial_sigma`` (the
  frames after the reference).

``--plot``: volume change and axial strains against frame, measured (with the 2-sigma bands of
the volume and of the axial strains) and truth, and their errors (matplotlib).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.layout import RESULTS
from triaxtrack.video import keyframe_indices


def _keyframes(results: Path) -> set[int]:
    videos = sorted(results.glob(RESULTS.simulated.video.format(camera="*")))
    return set(keyframe_indices(videos[0]).tolist()) if videos else set()


def _chunk_starts(results: Path) -> set[int]:
    starts = set()
    for f in results.glob(RESULTS.chunk_labels.format(camera="*", chunk="*")):
        frames = pd.read_parquet(f, columns=["frame"])["frame"]
        if len(frames):
            starts.add(int(frames.iloc[0]))
    return starts


def series_figures(results: Path) -> dict:
    sim_truth = RESULTS.simulated.truth
    v = pd.read_parquet(results / RESULTS.volume)
    t = pd.read_parquet(results / sim_truth.volume)
    m = v.merge(t, on="frame", suffixes=("", "_t"))
    v0 = float(m["volume_mm3_t"].iloc[0])
    dv = (m["volume_mm3"] - m["volume_mm3"].iloc[0]) - (m["volume_mm3_t"] - m["volume_mm3_t"].iloc[0])
    step = np.diff(dv.to_numpy()) / v0 * 100
    i = int(np.nanargmax(np.abs(step))) if len(step) else 0
    at = int(m["frame"].iloc[i + 1]) if len(step) else -1
    marks = {"chunk start": _chunk_starts(results), "keyframe": _keyframes(results)}
    where = ", ".join(k for k, s in marks.items() if at in s) or "inside a chunk and a GOP"
    out = {
        "frames": len(m),
        "dV_error_frame1_pct": float(dv.iloc[1] / v0 * 100) if len(m) > 1 else float("nan"),
        "largest_dV_step_pct": float(step[i]) if len(step) else float("nan"),
        "largest_step_into_frame": f"{at} ({where})",
    }
    for name, col in (("axial", "axial_strain"), ("local_axial", "local_axial_strain"),
                      ("volumetric", "volumetric_strain")):  # fmt: skip
        if col not in m:
            continue
        truth = m["volumetric_strain_t" if name == "volumetric" else "axial_strain_t"]
        out[f"{name}_std"] = float(m[col].std())
        out[f"{name}_max_error"] = float(np.nanmax(np.abs(m[col] - truth)))
    if "axial_sigma" in m:  # the frames after the reference (its own strain is 0 by definition)
        later = m[m["frame"] != m["reference_frame"]]
        z = (later["axial_strain"] - later["axial_strain_t"]) / later["axial_sigma"]
        out["axial_within_2sigma"] = float((np.abs(z) < 2).mean())
        out["axial_rms_error_over_sigma"] = float(np.sqrt((z**2).mean()))
    ve, s = m["volume_mm3"] - m["volume_mm3_t"], m["volume_sigma_mm3"]
    out["volume_within_2sigma"] = float((np.abs(ve) < 2 * s).mean())
    out["volume_rms_error_over_sigma"] = float(np.sqrt(((ve / s) ** 2).mean()))
    p = pd.read_parquet(results / RESULTS.points)
    tp = pd.read_parquet(results / sim_truth.points)
    pm = p.merge(tp, on=["frame", "id"], suffixes=("", "_t"))
    pm = pm[pm["id"] > 1000]
    e = np.sqrt(sum((pm[f"{c}_mm"] - pm[f"{c}_mm_t"]) ** 2 for c in "xyz"))
    r = e / pm["sigma_mm"]
    out["points_within_2sigma"] = float((r < 2).mean())
    out["points_rms_error_over_sigma"] = float(np.sqrt((r**2).mean()))
    return out


def plot(results: Path, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = pd.read_parquet(results / RESULTS.volume)
    t = pd.read_parquet(results / RESULTS.simulated.truth.volume)
    m = v.merge(t, on="frame", suffixes=("", "_t"))
    fig, ax = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    dv = m["volume_mm3"] - m["volume_mm3"].iloc[0]
    dvt = m["volume_mm3_t"] - m["volume_mm3_t"].iloc[0]
    ax[0, 0].plot(m["frame"], dvt, "k-", label="truth")
    ax[0, 0].plot(m["frame"], dv, ".-", label="measured")
    ax[0, 0].set_ylabel("volume change (mm$^3$)")
    ax[0, 0].legend()
    err = m["volume_mm3"] - m["volume_mm3_t"]
    ax[1, 0].fill_between(m["frame"], -2 * m["volume_sigma_mm3"], 2 * m["volume_sigma_mm3"], alpha=0.3,
                          label="2 sigma (volume_sigma_mm3)")  # fmt: skip
    ax[1, 0].plot(m["frame"], err, ".-", label="volume error")
    ax[1, 0].plot(m["frame"], dv - dvt, ".-", label="volume-change error")
    ax[1, 0].set_ylabel("error (mm$^3$)")
    ax[1, 0].set_xlabel("frame")
    ax[1, 0].legend(fontsize=8)
    ax[0, 1].plot(m["frame"], m["axial_strain_t"], "k-", label="truth")
    ax[0, 1].plot(m["frame"], m["axial_strain"], ".-", label="global (cap)")
    if "local_axial_strain" in m:
        ax[0, 1].plot(m["frame"], m["local_axial_strain"], ".-", label="local (middle third)")
    ax[0, 1].set_ylabel("axial strain")
    ax[0, 1].legend()
    if "local_axial_strain" in m:
        ax[1, 1].fill_between(m["frame"], -2 * m["local_axial_sigma"], 2 * m["local_axial_sigma"], alpha=0.3,
                              label="2 sigma (local)")  # fmt: skip
        ax[1, 1].plot(m["frame"], m["local_axial_strain"] - m["axial_strain_t"], ".-", label="local - truth")
    if "axial_sigma" in m:
        ax[1, 1].fill_between(m["frame"], -2 * m["axial_sigma"], 2 * m["axial_sigma"], alpha=0.5,
                              label="2 sigma (global, axial_sigma)")  # fmt: skip
    ax[1, 1].plot(m["frame"], m["axial_strain"] - m["axial_strain_t"], ".-", label="global - truth")
    ax[1, 1].set_ylabel("axial strain error")
    ax[1, 1].set_xlabel("frame")
    ax[1, 1].legend(fontsize=8)
    fig.suptitle(results.name)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", type=Path, nargs="+")
    p.add_argument("--plot", type=Path, help="figure path (one test)")
    args = p.parse_args()
    for r in args.results:
        print(r.name, json.dumps(series_figures(r), indent=1))
    if args.plot:
        plot(args.results[0], args.plot)


if __name__ == "__main__":
    main()
