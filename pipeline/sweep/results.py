"""The sweep table (``sweep.parquet``), its printed summary, and the stability bracket (C12)."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic_files import atomic_write_bytes
from pipeline.errors import LogError
from pipeline.sweep.grid import format_value
from pipeline.sweep.point import FIGURES

TABLE_NAME = "sweep.parquet"
LEAD = ["point"]
TAIL = ["status", "error", "ran", "analysed", "attempts", *FIGURES, "n_steps", "seconds", "worker",
        "spec_hash", "log"]


def _cell(v: Any) -> Any:
    return v if isinstance(v, bool | int | float | str) else json.dumps(v, sort_keys=True)


def make_table(keys: list[str], overrides: list[dict], records: list[dict]) -> pd.DataFrame:
    """One row per point, in grid order: point, the override columns, status, error, figures."""
    rows = [{"point": r["point"], **{k: _cell(o[k]) for k in keys},
             **{c: r.get(c) for c in TAIL}} for o, r in zip(overrides, records, strict=True)]
    df = pd.DataFrame(rows, columns=[*LEAD, *keys, *TAIL])
    for c in FIGURES:
        df[c] = df[c].astype(float)
    df["attempts"] = df["attempts"].fillna(0).astype(int)
    return df


def write_table(df: pd.DataFrame, path: Path, metadata: dict[str, str]) -> Path:
    """Write ``df`` to Parquet atomically, with ``pipeline.*`` schema metadata (a sweep's, a
    Monte Carlo's and a power study's tables)."""
    table = pa.Table.from_pandas(df, preserve_index=False)
    md = {**(table.schema.metadata or {}), **{k.encode(): v.encode() for k, v in metadata.items()}}
    buf = io.BytesIO()
    pq.write_table(table.replace_schema_metadata(md), buf, compression="zstd")
    atomic_write_bytes(path, buf.getvalue())
    return path


def read_sweep_table(path: Path | str) -> pd.DataFrame:
    """A ``sweep.parquet`` as a DataFrame (LogError naming the file if it is not one)."""
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: sweep table not found (run `make sweep`)")
    try:
        return pq.read_table(path).to_pandas()
    except (pa.ArrowInvalid, OSError) as exc:
        raise LogError(f"{path}: not a readable sweep table ({str(exc).splitlines()[0]})") from None


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "—" if math.isnan(v) else f"{v:.4g}"
    return str(v)


def summary_text(df: pd.DataFrame, keys: list[str], path: Path) -> str:
    """A fixed-width table of the points and a closing line with the counts."""
    cols = [*keys, "status", "ran", "dominant_lag1", "dt_mu_max", "eig_real", "spectral_radius"]
    heads = [*keys, "status", "ran", "lag-1", "dt·μ_max", "eig real", "ρ"]
    cached = (~df["ran"].astype(bool)) & (df["log"] != "")  # rows without a log never ran
    df = df.assign(ran=np.where(df["ran"], "run", np.where(cached, "cached", "—")))
    shown = dict.fromkeys(keys, format_value)
    cells = [[shown.get(c, _fmt)(row[c]) for c in cols] for _, row in df.iterrows()]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(heads)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(heads, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    n_fail = int((df["status"] != "complete").sum())
    n_retried = int((df["attempts"] > 1).sum())
    lines.append(f"{len(df)} points: {len(df) - n_fail} complete, {n_fail} failed; "
                 f"{int((df['ran'] == 'run').sum())} simulated now, {int(cached.sum())} from "
                 f"cache; {n_retried} retried -> {path}")
    for _, row in df[df["status"] != "complete"].iterrows():
        lines.append(f"  failed {row['point']}: {row['error']}")
    for _, row in df[df["attempts"] > 1].iterrows():
        lines.append(f"  retried {row['point']}: {int(row['attempts'])} attempts (a worker "
                     "died or retired while it ran)")
    return "\n".join(lines)


NEAR = 0.10  # points within 10 % of their predicted crossing are reported, not judged


def stability_bracket(sweep_table: pd.DataFrame | Path | str, key: str = "mission.dt",
                      lag: str = "dominant_lag1", predicted: str = "dt_star_damping",
                      unstable: str = "above") -> dict:
    """Where the measured lag-1 (column ``lag``) changes sign along ``key``, against the
    predicted crossing (column ``predicted``, in ``key`` units): by default the dominant
    lag-1 along mission.dt against dt* = 2/μ_max.

    Uses the complete rows sorted by ``key``. ``measured`` is the interval between the two
    grid points where the lag-1 changes sign (None unless it changes sign exactly once);
    ``predicted`` is the interval between the grid points that bracket the predicted crossing
    (the median over the points; its spread is ``dt_star_range``). ``holds`` is true when
    the sign changes exactly once and every point's predicted crossing lies in the measured
    interval (``lo < crossing <= hi``). The keys say ``dt_star`` whatever the column. A
    complete point with a NaN lag-1 (``undefined_lag1``) makes neither hold.

    Point by point: the prediction is period-2 on the ``unstable`` side of the point's
    crossing (``above`` it for a time step, ``below`` it for a bus inertia), the measurement
    a negative lag-1. ``far_agree`` is true when they agree at every point more than
    ``NEAR`` (10 %) away from its crossing; the points nearer are listed in ``near``.
    """
    df = (sweep_table if isinstance(sweep_table, pd.DataFrame)
          else read_sweep_table(sweep_table))
    for col in (key, lag, predicted):
        if col not in df.columns:
            raise LogError(f"sweep table has no column {col!r} (columns: "
                           f"{', '.join(df.columns)})")
    complete = df[df["status"] == "complete"]
    # A complete point whose lag-1 is NaN is no evidence either way, and no bracket holds on it.
    undefined = [float(v) for v in complete.loc[complete[lag].isna(), key]]
    ok = complete[complete[lag].notna()].sort_values(key)
    x = ok[key].to_numpy(float)
    lag_values = ok[lag].to_numpy(float)
    stars = ok[predicted].dropna().to_numpy(float)
    flips = [(float(x[i]), float(x[i + 1])) for i in range(len(x) - 1)
             if np.sign(lag_values[i]) != np.sign(lag_values[i + 1])]
    dt_star = float(np.median(stars)) if stars.size else math.nan
    below, above = x[x <= dt_star], x[x > dt_star]
    predicted_bracket = (float(below.max()) if below.size else None,
                         float(above.min()) if above.size else None)
    measured = flips[0] if len(flips) == 1 else None
    holds = bool(measured is not None and stars.size and not undefined
                 and all(measured[0] < s <= measured[1] for s in stars))
    crossing = ok[predicted].to_numpy(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.abs(x / crossing - 1.0)
    side = x > crossing if unstable == "above" else x < crossing
    judged = rel > NEAR  # NaN (no crossing) is near: reported, not judged
    agree = (lag_values < 0) == side
    near = [{"x": float(x[i]), "lag1": float(lag_values[i]), "crossing": float(crossing[i])}
            for i in np.flatnonzero(~judged)]
    return {
        "key": key, "lag": lag, "predicted_column": predicted, "n_points": len(df),
        "n_complete": len(ok), "grid": x.tolist(), "lag1": lag_values.tolist(),
        "flips": flips, "measured": measured, "dt_star": dt_star,
        "dt_star_range": (float(stars.min()), float(stars.max())) if stars.size else None,
        "predicted": predicted_bracket, "holds": holds,
        "n_far": int(judged.sum()),
        "far_agree": bool(judged.any() and agree[judged].all() and not undefined),
        "undefined_lag1": undefined,
        "far_disagree": [float(v) for v in x[judged & ~agree]], "near": near,
    }
