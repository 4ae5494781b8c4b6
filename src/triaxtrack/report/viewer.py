"""A self-contained 3-D viewer of the specimen (:func:`viewer_html`): one offline HTML page
(plotly, its JavaScript inlined, nothing fetched from the network) showing the membrane surface
coloured by a strain component, with a time slider over the processed frames; the workflow's
stage, from a test's files to the page (:func:`run_specimen_viewer`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from triaxtrack.export import MembraneFrame, grid_quads, measured_membrane_frames
from triaxtrack.report.config import ReportConfig
from triaxtrack.volume.config import VolumeConfig

STRAIN_LABELS = {"e_zz": "axial strain e_zz (%)", "e_tt": "circumferential strain e_tt (%)",
                 "e_tz": "shear strain e_tz (%)"}  # fmt: skip
COLOUR_PERCENTILE = 99  # the colour range: this percentile of |strain| over the frames shown


def _triangles(n_r: int, n_c: int) -> np.ndarray:
    q = grid_quads(n_r, n_c)
    return np.vstack([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


def viewer_html(
    frames: Sequence[MembraneFrame], colour_by: str = "e_zz", title: str = "specimen",
    skipped: Sequence[tuple[int, str]] = (),
) -> str:  # fmt: skip
    """The page: a plotly Mesh3d of each frame's membrane surface (mm, cell frame), coloured by
    ``colour_by`` (Green-Lagrange, tension positive, %, a diverging scale symmetric about 0),
    one slider step per frame (its test-clock time), play and pause buttons.
    ``include_plotlyjs=True``: the page works offline. Without frames, a page that says so and
    gives the reasons of the frames not shown (``skipped``: (frame, reason))."""
    import plotly.graph_objects as go

    if not frames:
        from collections import Counter
        from html import escape

        why = "".join(f"<li>{escape(r)} ({n} frames)</li>" for r, n in Counter(r for _, r in skipped).items())
        head = f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{escape(title)}</title></head>"
        return (f"{head}<body><h1>{escape(title)}</h1><p>No frame of this test could be measured, so "
                f"there is no surface to show (volume.parquet gives each frame's reason).</p>"
                f"<ul>{why}</ul></body></html>")  # fmt: skip
    if colour_by not in STRAIN_LABELS:
        raise ValueError(f"colour_by must be one of {sorted(STRAIN_LABELS)}, not {colour_by!r}")
    n_r, n_c = frames[0].xyz.shape[:2]
    tri = _triangles(n_r, n_c).astype(np.int32)
    values = [100 * f.point_data[colour_by].ravel() for f in frames]
    lim = float(np.nanpercentile(np.abs(np.concatenate(values)), COLOUR_PERCENTILE)) or 1e-3

    def mesh(f: MembraneFrame, v: np.ndarray, full: bool):
        """The trace; a slider frame carries only what changes (the points and colours: plotly
        merges it into the first frame's trace, triangles and colour scale included)."""
        p = f.xyz.reshape(-1, 3).astype(np.float32)  # float32: 0.01 um at 100 mm, half the page
        moving = {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2], "intensity": v.astype(np.float32)}
        if not full:
            return go.Mesh3d(**moving)
        return go.Mesh3d(
            **moving, i=tri[:, 0], j=tri[:, 1], k=tri[:, 2], cmin=-lim, cmax=lim, colorscale="RdBu_r",
            colorbar={"title": {"text": STRAIN_LABELS[colour_by]}}, flatshading=False,
        )  # fmt: skip

    names = [f"{f.time_s:.2f} s (frame {f.frame})" for f in frames]
    fig = go.Figure(
        data=[mesh(frames[0], values[0], True)],
        frames=[
            go.Frame(data=[mesh(f, v, False)], name=n) for f, v, n in zip(frames, values, names, strict=True)
        ],
    )
    steps = [{"method": "animate", "label": n, "args": [[n], {"mode": "immediate", "frame": {"duration": 0,
             "redraw": True}, "transition": {"duration": 0}}]} for n in names]  # fmt: skip
    fig.update_layout(
        title=f"{title}: membrane surface coloured by {STRAIN_LABELS[colour_by]} (tension positive)",
        scene={"aspectmode": "data", "xaxis_title": "x (mm)", "yaxis_title": "y (mm)",
               "zaxis_title": "z (mm)"},
        sliders=[{"steps": steps, "currentvalue": {"prefix": "time "}, "pad": {"t": 30}}],
        updatemenus=[{"type": "buttons", "showactive": False, "x": 0.05, "y": 0.05, "buttons": [
            {"label": "play", "method": "animate", "args": [None, {"frame": {"duration": 150, "redraw": True},
                                                                    "fromcurrent": True}]},
            {"label": "pause", "method": "animate", "args": [[None], {"mode": "immediate",
                                                                       "frame": {"duration": 0}}]},
        ]}],
        height=800,
    )  # fmt: skip
    return fig.to_html(include_plotlyjs=True, full_html=True, include_mathjax=False,
                       config={"displaylogo": False})  # fmt: skip


def run_specimen_viewer(
    *,
    volume: str | Path,
    points: str | Path,
    kit: str | Path,
    html: str | Path,
    report_cfg: dict,
    volume_cfg: dict,
    name: str,
) -> None:
    """Rule specimen_viewer: :func:`viewer_html` titled ``name`` of up to ``viewer_max_frames`` of
    the frames ``volume`` measured (:func:`~triaxtrack.export.measured_membrane_frames` of the kit
    folder ``kit`` and ``points``), coloured by ``viewer_colour_by``, written to ``html``; prints
    how many frames it shows. ``report_cfg``, ``volume_cfg``: the config's ``report``
    (:class:`ReportConfig`) and ``volume`` (:class:`~triaxtrack.volume.VolumeConfig`) sections."""
    cfg, volume_config = ReportConfig.from_dict(report_cfg), VolumeConfig.from_dict(volume_cfg)
    series = list(measured_membrane_frames(kit, volume, points, volume_config, cfg.viewer_max_frames))
    shown = [f for f in series if isinstance(f, MembraneFrame)]
    skipped = [f for f in series if not isinstance(f, MembraneFrame)]
    Path(html).write_text(viewer_html(shown, cfg.viewer_colour_by, name, skipped))
    print(f"viewer: {len(shown)} of {len(series)} frames")
