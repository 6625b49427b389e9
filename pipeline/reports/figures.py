"""Figures of the reports (matplotlib, Agg backend), written as PNG under ``figures/``.

Every figure is drawn from analysis.json records and the logs they name; a figure whose inputs
are missing is skipped (and the page says so) rather than drawn from anything else.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from pipeline.logs import atomic_write_bytes, read_columns
from pipeline.sim.sampling import scale_by_svd

plt.rcParams.update({"figure.dpi": 100, "font.size": 9, "axes.grid": True, "grid.alpha": 0.3})


@dataclass(frozen=True)
class Figure:
    file: str  # relative to the report folder, e.g. figures/rates.png
    title: str
    caption: str


@dataclass(frozen=True)
class RunData:
    """An analysed run: its record and the path of its log (None if the log is gone)."""

    name: str
    record: dict
    log: Path | None
    spec: dict  # the resolved spec from the log's metadata ({} without a log)
    folder: str  # the folder of analysis.json under the report root

    @property
    def description(self) -> str:
        return str(self.spec.get("description", ""))

    @property
    def conditioning(self) -> tuple[float, float, float] | None:
        try:
            c = self.spec["controller"]["base"]["conditioning"]
            return float(c["low"]), float(c["high"]), float(c["floor"])
        except (KeyError, TypeError):
            return None


def label(text: str) -> str:
    """Plain text for matplotlib (no mathtext from a spec name)."""
    return str(text).replace("$", r"\$")


def _save(fig, path: Path) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def _cols(run: RunData, cols: list[str]) -> dict[str, np.ndarray]:
    return read_columns(run.log, cols)


def rates(runs: list[RunData], path: Path) -> None:
    """‖ω_b‖ over the mission, and the bus yaw rate ω_b,z and the camera roll rate over the
    last second, per run."""
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(8, 8))
    for r in runs:
        c = _cols(r, ["t", "v_breve"])
        w = c["v_breve"][:, 0:3]
        a1.plot(c["t"], np.linalg.norm(w, axis=1), lw=0.8, label=label(r.name))
        last = c["t"] >= c["t"][-1] - 1.0
        for ax, i in ((a2, 2), (a3, 8)):
            ax.plot(c["t"][last], c["v_breve"][last, i], lw=0.8, marker=".", ms=2,
                    label=label(r.name))
    a1.set(title="bus angular rate ‖ω_b‖", xlabel="t (s)", ylabel="rad/s")
    a2.set(title="bus yaw rate ω_b,z = v̆[2] (last 1 s)", xlabel="t (s)", ylabel="rad/s")
    a3.set(title="camera roll rate ω_e,z = v̆[8] (last 1 s)", xlabel="t (s)", ylabel="rad/s")
    a1.legend(fontsize=7, ncols=2)
    fig.tight_layout()
    _save(fig, path)


def divergence_growth(run: RunData, path: Path) -> None:
    """|Δω_b| per step of a diverged run on a log scale, with the fitted and the predicted
    growth (eqs. 22, 23)."""
    g = run.record["divergence"]
    c = _cols(run, ["v_breve"])
    x = c["v_breve"][:, 0:3] @ np.array(g["direction"])
    d = np.abs(np.diff(x))
    k = np.arange(d.size)
    fig, ax = plt.subplots(figsize=(7, 3.8))
    ax.semilogy(k, np.maximum(d, 1e-300), "o-", ms=4, lw=0.8, color="0.3",
                label="|x_{k+1} − x_k|, x = ω_b along its step direction")
    k0, k1 = g["fit_steps"]
    ref = d[k0]
    kk = np.arange(k0, k1)
    for factor, style, what in ((g["predicted"], "--", "Φ, simulator's update order"),
                                (g["predicted_note_order"], ":", "Φ, the note's update order")):
        ax.semilogy(kk, ref * abs(factor) ** (kk - k0), style, lw=1.2,
                    label=f"{what}: ×{abs(factor):.4g} per step")
    ax.axvline(g["first_limit_step"], color="r", lw=0.8,
               label=f"first limit flag (step {g['first_limit_step']})")
    ax.set(title=label(f"{run.name}: growth per step {g['growth_factor']:+.4g} (measured)"),
           xlabel="step k", ylabel="rad/s")
    ax.legend(fontsize=7, loc="upper left")
    _save(fig, path)


def lag1_directions(runs: list[RunData], path: Path) -> None:
    """Lag-1 autocorrelation of each singular direction of Γ, per run; dominant marked."""
    fig, ax = plt.subplots(figsize=(8, 3.6))
    width = 0.8 / max(len(runs), 1)
    for j, r in enumerate(runs):
        d = r.record["directions"]
        x = np.arange(len(d)) + (j - (len(runs) - 1) / 2) * width
        ax.bar(x, [e["lag1"] for e in d], width, label=label(r.name))
        dom = r.record["dominant"]["index"]
        ax.plot(x[dom], d[dom]["lag1"], "k*", ms=9)
    ax.axhline(0, color="k", lw=0.6)
    ax.set(title="lag-1 autocorrelation per direction (★ dominant)", xlabel="direction i "
           "(singular values descending)", ylabel="r₁", ylim=(-1.05, 1.05))
    ax.legend(fontsize=7, ncols=3, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    _save(fig, path)


def eigenvalues(run: RunData, path: Path) -> None:
    """Eigenvalues of the 18×18 map for both integrators, against the unit circle."""
    th = run.record["theory"]
    fig, ax = plt.subplots(figsize=(5, 5))
    t = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(t), np.sin(t), "k-", lw=0.8, label="unit circle")
    for integ, mk in (("explicit", "x"), ("imex", "o")):
        ev = th["maps"][integ]["eigenvalues"]
        ax.plot(ev["real"], ev["imag"], mk, mfc="none", ms=7,
                label=f"{integ}: ρ = {th['maps'][integ]['spectral_radius']:.4g}")
    lim = max(1.2, 1.1 * max(m["spectral_radius"] for m in th["maps"].values()))
    ax.set(xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal", xlabel="Re λ", ylabel="Im λ",
           title=label(f"Φ at step {th['step']} of {run.name} (dt {th['dt']:g} s)"))
    ax.legend(fontsize=7, loc="lower left")
    _save(fig, path)


def gamma_ramp(runs: list[RunData], path: Path) -> None:
    """The γ ramp of the spec's conditioning knobs, with the logged (s_min_G, γ) of each run."""
    fig, ax = plt.subplots(figsize=(6, 3.8))
    knobs = None
    for r in runs:
        c = _cols(r, ["s_min_G", "gamma"])
        ax.plot(c["s_min_G"], c["gamma"], ".", ms=3, alpha=0.6, label=label(f"{r.name} (logged)"))
        knobs = knobs or r.conditioning
    low, high, floor = knobs or (0.01, 0.05, 0.3)
    smax = max([high * 2] + [float(_cols(r, ["s_min_G"])["s_min_G"].max()) * 1.1 for r in runs])
    s = np.linspace(0, smax, 500)
    ax.plot(s, [scale_by_svd(x, low, high, floor) for x in s], "k-", lw=1.2,
            label=f"scale_by_svd (low {low:g}, high {high:g}, floor {floor:g})")
    ax.set(title="γ ramp and the logged s_min_G", xlabel="σ_min(Γ)", ylabel="γ",
           ylim=(0, 1.08))
    ax.legend(fontsize=7, loc="lower right")
    _save(fig, path)


def conditioning(runs: list[RunData], path: Path) -> None:
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for r in runs:
        c = _cols(r, ["t", "s_min_G", "s_min_J", "kappa_G"])
        a1.plot(c["t"], c["s_min_G"], lw=0.9, label=label(f"{r.name}: σ_min(Γ)"))
        a1.plot(c["t"], c["s_min_J"], lw=0.7, ls="--", label=label(f"{r.name}: σ_min(J⊕)"))
        a2.semilogy(c["t"], c["kappa_G"], lw=0.9, label=label(r.name))
    a1.set(title="conditioning over the mission", ylabel="σ_min")
    a2.set(xlabel="t (s)", ylabel="κ(Γ)")
    a1.legend(fontsize=6, ncols=2)
    a2.legend(fontsize=7)
    fig.tight_layout()
    _save(fig, path)


def dt_mu(runs: list[RunData], path: Path) -> None:
    fig, ax = plt.subplots(figsize=(8, 3.4))
    for r in runs:
        c = _cols(r, ["t", "dt_mu_max"])
        ax.plot(c["t"], c["dt_mu_max"], lw=0.9,
                label=label(f"{r.name} ({r.record.get('integrator', '?')})"))
    ax.axhline(2.0, color="r", lw=1.2, ls="--", label="2: forward-Euler bound")
    ax.set(title="dt·μ_max over the mission", xlabel="t (s)", ylabel="dt·μ_max", ylim=(0, None))
    ax.legend(fontsize=7)
    _save(fig, path)


def sweep_map(table: Path, path: Path) -> str | None:
    """dt-sweep stability map from a sweep.parquet; returns why it was skipped, if it was."""
    df = pd.read_parquet(table)
    lag = "dominant_lag1" if "dominant_lag1" in df else "lag1"
    need = ["mission.dt", "dt_mu_max", lag]
    missing = [c for c in need if c not in df]
    if missing:
        return f"{table}: no column {', '.join(missing)}"
    if "status" in df:
        df = df[df["status"] == "complete"]
    df = df.assign(**{"mission.dt": pd.to_numeric(df["mission.dt"], errors="coerce")})
    df = df.dropna(subset=need).sort_values("mission.dt")
    if df.empty:
        return f"{table}: no complete point"
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    unstable = df["dt_mu_max"] > 2
    for ax, col, ttl in ((a1, lag, "dominant lag-1"), (a2, "dt_mu_max", "dt·μ_max")):
        ax.plot(df["mission.dt"], df[col], "-", color="0.6", lw=0.8)
        ax.plot(df["mission.dt"][~unstable], df[col][~unstable], "o", color="tab:green",
                label="dt·μ_max < 2")
        ax.plot(df["mission.dt"][unstable], df[col][unstable], "s", color="tab:red",
                label="dt·μ_max > 2")
        if "dt_star_damping" in df and df["dt_star_damping"].notna().any():
            ax.axvline(float(df["dt_star_damping"].median()), color="k", ls="--", lw=0.8,
                       label=f"dt*_damping = {float(df['dt_star_damping'].median()):.4g} s")
        ax.set(title=ttl, xlabel="mission.dt (s)")
    a2.axhline(2.0, color="r", lw=0.8)
    a1.legend(fontsize=7)
    fig.suptitle(label(f"dt sweep {table.parent.name}"))
    fig.tight_layout()
    _save(fig, path)
    return None


def sweep_key(table: Path) -> str | None:
    """The swept key of a sweep table (its schema metadata), or None if unreadable."""
    import pyarrow.parquet as pq

    try:
        md = pq.read_schema(table).metadata or {}
    except (OSError, ValueError):
        return None
    keys = md.get(b"pipeline.keys", b"").decode().split(",")
    return next((k for k in keys if k != "mission.duration"), None)


def inertia_map(table: Path, path: Path) -> str | None:
    """ω_b's lag-1 and period-2 amplitude against I_zz,bus over a bus-inertia sweep, with the
    predicted crossing; returns why it was skipped, if it was."""
    df = pd.read_parquet(table)
    need = ["I_zz_bus", "bus_rate_lag1", "bus_rate_alternating_rms", "bus_critical_I_zz"]
    missing = [c for c in need if c not in df]
    if missing:
        return f"{table}: no column {', '.join(missing)}"
    df = df[df["status"] == "complete"].dropna(subset=need).sort_values("I_zz_bus")
    if df.empty:
        return f"{table}: no complete point"
    crit = float(df["bus_critical_I_zz"].median())
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    ring = df["bus_rate_lag1"] < 0
    for ax, col, ttl, ylab in (
            (a1, "bus_rate_lag1", "lag-1 of ω_b's dominant step component", "r₁"),
            (a2, "bus_rate_alternating_rms", "ω_b period-2 amplitude", "rad/s")):
        ax.plot(df["I_zz_bus"], df[col], "-", color="0.6", lw=0.8)
        ax.plot(df["I_zz_bus"][ring], df[col][ring], "s", color="tab:red", label="r₁ < 0")
        ax.plot(df["I_zz_bus"][~ring], df[col][~ring], "o", color="tab:green", label="r₁ ≥ 0")
        ax.axvline(crit, color="k", ls="--", lw=0.8,
                   label=f"predicted I_zz,bus = dt·D_b/2 = {crit:.4g} kg·m²")
        ax.set_xscale("log")
        ax.set(title=ttl, xlabel="I_zz,bus (kg·m²)", ylabel=ylab)
    a2.set_yscale("log")
    a1.set_ylim(-1.05, 1.05)
    a1.legend(fontsize=7, loc="center right")
    fig.suptitle(label(f"bus-inertia sweep {table.parent.name}"))
    fig.tight_layout()
    _save(fig, path)
    return None
