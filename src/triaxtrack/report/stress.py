"""The report's stress-strain charts (matplotlib, Agg): deviator stress, volumetric strain and
Young's modulus against axial strain, from ``stress_strain.parquet``
(:data:`~triaxtrack.tables.STRESS_STRAIN`).

Conventions: strains compression positive, drawn in per cent; stresses and moduli in kPa and
MPa; the measured axial strain (the cameras' top cap) on the x axes unless a series says
otherwise; bands are +- 1 standard uncertainty. The workflow's stage, from the table to the
PNG files: :func:`run_stress_figures`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from triaxtrack.report.style import PALETTE, new_figure, no_data, save_figure, styled
from triaxtrack.tables import STRESS_STRAIN, read_table

__all__ = ["modulus_figure", "q_strain_figure", "run_stress_figures", "volumetric_figure"]


def _finite(*arrays: np.ndarray) -> bool:
    return all(np.isfinite(np.asarray(a, float)).any() for a in arrays)


def _axes(
    stress: pd.DataFrame, width_px: int, height_px: int, **labels: str
) -> tuple[pd.DataFrame, Figure, Axes]:
    """``stress`` in frame order, and a new figure with one axes set with ``labels``."""
    fig = new_figure(width_px, height_px)
    ax = fig.subplots()
    ax.set(**labels)
    return stress.sort_values("frame"), fig, ax


@styled
def q_strain_figure(stress: pd.DataFrame, width_px: int = 900, height_px: int = 520) -> Figure:
    """Deviator stress q (kPa) against axial strain (%): on the measured mean area V/H (with its
    +- 1 sigma band), the mid-height section and the smallest section, against the measured
    strain; the lab's standard q (A0 (1 - ev) / (1 - ea), the log's strain) against the log's
    strain."""
    s, fig, ax = _axes(stress, width_px, height_px, title="deviator stress against axial strain",
                       xlabel="axial strain (%, compression positive)", ylabel="q (kPa)")  # fmt: skip
    ea = 100 * s["axial_strain"].to_numpy(float)
    if not _finite(ea, s["q_mean_kpa"]):
        no_data(ax)
        return fig
    q = s["q_mean_kpa"].to_numpy(float)
    sig = s["q_mean_sigma_kpa"].to_numpy(float)
    ax.fill_between(ea, q - sig, q + sig, color=PALETTE[0], alpha=0.25, lw=0)
    ax.plot(ea, q, color=PALETTE[0], lw=1.8, label="measured mean area V/H")
    ax.plot(ea, s["q_mid_kpa"], color=PALETTE[1], lw=1.2, label="measured mid-height section")
    ax.plot(ea, s["q_min_kpa"], color=PALETTE[2], lw=1.2, label="measured smallest section")
    ax.plot(100 * s["axial_strain_log"], s["q_standard_kpa"], color=PALETTE[7], lw=1.2, ls="--",
            label="standard: A0 (1 - ev) / (1 - ea), log's strain")  # fmt: skip
    ax.legend(loc="lower right")
    return fig


@styled
def volumetric_figure(stress: pd.DataFrame, width_px: int = 900, height_px: int = 420) -> Figure:
    """Volumetric strain (%) against axial strain (%): measured by the cameras, and from the
    log's volume gauge (over the nominal volume) against the log's strain where the log has one."""
    title = "volumetric strain against axial strain (contraction positive)"
    s, fig, ax = _axes(stress, width_px, height_px, title=title, xlabel="axial strain (%)",
                       ylabel="volumetric strain (%)")  # fmt: skip
    if not _finite(s["axial_strain"], s["volumetric_strain"]):
        no_data(ax)
        return fig
    ax.plot(100 * s["axial_strain"], 100 * s["volumetric_strain"], color=PALETTE[0], lw=1.8,
            label="measured (cameras)")  # fmt: skip
    if _finite(s["volumetric_strain_gauge"]):
        ax.plot(100 * s["axial_strain_log"], 100 * s["volumetric_strain_gauge"], color=PALETTE[3], lw=1.2,
                ls="--", label="load frame's volume gauge")  # fmt: skip
    ax.legend(loc="best")
    return fig


@styled
def modulus_figure(stress: pd.DataFrame, width_px: int = 900, height_px: int = 420) -> Figure:
    """Secant (with its +- 1 sigma band) and tangent Young's modulus (MPa) against the measured
    axial strain (%) on a logarithmic axis (strains > 0 only)."""
    s, fig, ax = _axes(stress, width_px, height_px, title="Young's modulus against axial strain",
                       xlabel="axial strain (%, log scale)", ylabel="E (MPa)")  # fmt: skip
    ea = 100 * s["axial_strain"].to_numpy(float)
    sec = s["e_secant_kpa"].to_numpy(float) / 1000
    if not _finite(np.where(ea > 0, sec, np.nan)):
        no_data(ax)
        return fig
    ok = ea > 0
    sig = s["e_secant_sigma_kpa"].to_numpy(float) / 1000
    ax.fill_between(ea[ok], (sec - sig)[ok], (sec + sig)[ok], color=PALETTE[0], alpha=0.25, lw=0)
    ax.plot(ea[ok], sec[ok], color=PALETTE[0], lw=1.8, label="secant q / ea")
    tan = s["e_tangent_kpa"].to_numpy(float) / 1000
    ax.plot(ea[ok], tan[ok], color=PALETTE[1], lw=0, marker=".", ms=4, label="tangent dq / dea (local line)")
    ax.set_xscale("log")
    top = np.nanpercentile(np.r_[sec[ok], tan[ok & np.isfinite(tan)]], 99) if ok.any() else 1.0
    ax.set_ylim(0, 1.1 * top)
    ax.legend(loc="upper right")
    return fig


def run_stress_figures(
    *, stress: str | Path, q_strain_png: str | Path, volumetric_png: str | Path, modulus_png: str | Path
) -> None:
    """Rule stress_figures: :func:`q_strain_figure`, :func:`volumetric_figure` and
    :func:`modulus_figure` of the ``stress`` table (``stress_strain.parquet``), as PNG files."""
    table = read_table(stress, STRESS_STRAIN)
    save_figure(q_strain_figure(table), q_strain_png)
    save_figure(volumetric_figure(table), volumetric_png)
    save_figure(modulus_figure(table), modulus_png)
