"""What a sweep writes besides its variants: the summary table and the contact sheet.

``summary.csv`` (and ``summary.parquet`` when pyarrow is installed): one row per variant —
its index, the value of every varied field, ``status`` (passes | fails | error), the exit
code, total energy (J·s-like, the audit's Σ α Q² dt summed over characters), seconds, then
per goal and coupling ``<name>.measured`` and ``<name>.holds``, and per character the
audit figures ``<character>.root_residual_rel`` (body weight), ``.footstep_error_max`` (m),
``.penetration_max`` (m), ``.friction_violation_max`` (N).

``contact_sheet.png``: one preview frame (the middle of the scene, side camera) per variant
in a grid, titled with the variant's values; drawn with :mod:`scenegraph.export.preview`.
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from schedules.execution.checkpoints import atomic_write, atomic_write_text

__all__ = ["summary_row", "write_summary", "write_contact_sheet", "AUDIT_FIELDS"]

AUDIT_FIELDS = ("root_residual_rel", "footstep_error_max", "penetration_max", "friction_violation_max")


def summary_row(index: int, assignment, outcome: dict) -> dict:
    """One CSV row from a variant's outcome (``{"report": ..., "exit_code": ..., "error": ...}``)."""
    row: dict = {"variant": index}
    for p, v in assignment:
        row[p] = v
    rep = outcome.get("report")
    row["exit_code"] = outcome.get("exit_code")
    if rep is None:
        row["status"] = "error"
        row["error"] = outcome.get("error", "")
        return row
    row["status"] = "passes" if rep.get("passes") else "fails"
    if "edit" in rep:  # an edit scenario (schedules/execution/edit_run.py): no solver, no energy
        for k in ("momentum_corr", "parabola_rms_mm", "naive_parabola_rms_mm", "ang_mom_drift", "edit_seconds"):
            row[k] = rep.get(k)
    else:
        row["energy"] = sum(c["energy"] for c in rep["characters"].values())
    row["seconds"] = rep.get("total_seconds")
    for n, e in {**rep.get("goals", {}), **rep.get("couplings", {})}.items():
        row[f"{n}.measured"] = e.get("measured")
        row[f"{n}.holds"] = e.get("holds")
    for who, c in rep["characters"].items():
        for k in AUDIT_FIELDS:
            row[f"{who}.{k}"] = c["audit"].get(k)
    return row


def write_summary(rows: list[dict], out_dir: Path) -> list[Path]:
    """``summary.csv`` (+ ``summary.parquet`` with pyarrow); returns the files written."""
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, "") for k in cols})
    written = [atomic_write_text(buf.getvalue(), out_dir / "summary.csv")]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    table = pa.table({c: [None if r.get(c) is None else str(r.get(c)) for r in rows] for c in cols})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    written.append(atomic_write(out_dir / "summary.parquet", sink.getvalue().to_pybytes()))
    return written


def write_contact_sheet(stages: list[tuple[str, Path]], out: Path, *, camera: str | None = None) -> Path | None:
    """One middle frame per stage in a grid; None when no stage exists."""
    from scenegraph.export.preview import (_atomic_save, _draw_frame, _mpl, _scene_bounds, parse_camera,
                                    scene_from_stage)

    stages = [(label, p) for label, p in stages if Path(p).is_file()]
    if not stages:
        return None
    _, Figure = _mpl()
    cam = parse_camera(camera)
    ncol = min(4, len(stages))
    nrow = int(math.ceil(len(stages) / ncol))
    fig = Figure(figsize=(3.0 * ncol, 2.6 * nrow + 0.3))
    for i, (label, p) in enumerate(stages):
        scene = scene_from_stage(p)
        k = len(scene.times) // 2
        ax = fig.add_subplot(nrow, ncol, i + 1)
        _draw_frame(ax, scene, k, cam, range(len(scene.times)), _scene_bounds(scene, cam, range(len(scene.times))),
                    title=False)
        ax.set_title(f"{label}\nt = {float(np.asarray(scene.times)[k]):.2f} s", fontsize=7)
    fig.tight_layout()
    return _atomic_save(fig, Path(out), dpi=90)
