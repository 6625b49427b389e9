"""Figures of the reports (matplotlib, Agg backend), written as PNG under ``figures/``.

Every figure is drawn from analysis.json records and the logs they name; a figure whose inputs
are missing is skipped (and the page says so) rather than drawn from anything else.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import MaxNLocator

from pipeline.analysis.schema import AnalysisRecord
from pipeline.atomic_files import atomic_write_bytes
from pipeline.errors import LogError
from pipeline.logs import VerifiedLog
from pipeline.shapes import BREVE
from pipeline.sim.sampling import scale_by_svd
from pipeline.sim.stability import axis_symbol

# Legends at 8 pt at least: at the page's width a 6–7 pt legend is unreadable.
plt.rcParams.update({"figure.dpi": 100, "font.size": 9, "legend.fontsize": 8,
                     "axes.grid": True, "grid.alpha": 0.3})
LEGEND_MIN_PT = 8.0
DIMLESS = "dimensionless"


@dataclass(frozen=True)
class Figure:
    file: str  # relative to the report folder, e.g. figures/rates.png
    title: str
    caption: str


@dataclass(frozen=True)
class RunData:
    """An analysed run: its record and the verified log it was made from (None if that log
    is gone, damaged or re-run since), and the log of the run it is compared with (likewise)."""

    name: str
    record: AnalysisRecord
    log: VerifiedLog | None
    spec: dict  # the resolved spec from the log's metadata ({} without a log)
    folder: str  # the folder of analysis.json under the report root
    against: VerifiedLog | None = None

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


@dataclass(frozen=True)
class RunStyle:
    """How one run is drawn in every figure: colour, line style and marker."""

    color: str
    ls: str | tuple
    marker: str


# One style per run, the same in every figure and every report: the colour says which run
# (robot and role), the line style and marker say the role, so runs whose lines coincide (the
# nominal and imex missions share dt·μ_max) stay distinguishable, also in grey print.
_ROLES = ("imex", "dt010", "reach", "unbounded")  # matched in the name; otherwise "nominal"
_PALETTE = {
    ("seed", "nominal"): "#d62728", ("seed", "dt010"): "#1f77b4", ("seed", "imex"): "#2ca02c",
    ("seed", "reach"): "#ff7f0e", ("seed", "unbounded"): "#7f7f7f",
    ("servicer", "nominal"): "#9467bd", ("servicer", "dt010"): "#17becf",
    ("servicer", "imex"): "#8c564b", ("servicer", "reach"): "#e377c2",
    ("servicer", "unbounded"): "#bcbd22",
}
_LINESTYLE = {"nominal": "-", "dt010": (0, (6, 2)), "imex": (0, (1.5, 1.5)),
              "reach": (0, (6, 2, 1.5, 2)), "unbounded": (0, (3, 1, 1, 1, 1, 1))}
_MARKER = {"nominal": "o", "dt010": "s", "imex": "^", "reach": "D", "unbounded": "x"}
# For runs whose name gives a style another run already has (a user's own specs).
_SPARE = ("#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173", "#3182bd", "#e6550d",
          "#31a354", "#756bb1", "#636363")


def run_style(name: str) -> RunStyle:
    """The style of a run from its name: robot (``servicer`` or the seed robot) and role."""
    low = name.lower()
    role = next((r for r in _ROLES if r in low), "nominal")
    robot = "servicer" if "servicer" in low else "seed"
    return RunStyle(_PALETTE[(robot, role)], _LINESTYLE[role], _MARKER[role])


def palette(names: list[str]) -> dict[str, RunStyle]:
    """A distinct style per run: :func:`run_style`, and a spare colour for a run whose colour
    another run already has. Names that say their role or robot are served first, so
    ``nominal`` keeps its colour beside a user's ``alpha``. Computed once over a report's
    runs, so every figure of the report draws a run alike."""
    out: dict[str, RunStyle] = {}
    taken: set[str] = set()
    spare = iter(_SPARE * (1 + len(names) // len(_SPARE)))

    def says(name: str) -> bool:
        return any(k in name.lower() for k in (*_ROLES, "nominal", "servicer"))

    for name in sorted(set(names), key=lambda n: (not says(n), n)):
        st = run_style(name)
        if st.color in taken:
            st = RunStyle(next(spare), st.ls, st.marker)
        taken.add(st.color)
        out[name] = st
    return out


def _styles(runs: list[RunData], styles: dict[str, RunStyle] | None) -> dict[str, RunStyle]:
    return styles if styles is not None else palette([r.name for r in runs])


def _line_kw(st: RunStyle, j: int, n_runs: int, n_points: int) -> dict:
    """Line keywords for the j-th of n_runs overlaid runs: earlier runs drawn wider beneath
    later ones, and markers staggered along the line, so coinciding lines all show."""
    every = max(n_points // 8, 1)
    return {"color": st.color, "ls": st.ls, "lw": 1.0 + 2.4 * (n_runs - 1 - j) / max(n_runs, 1),
            "marker": st.marker, "ms": 4.5, "mfc": "none",
            "markevery": (int(j * every / max(n_runs, 1)), every), "zorder": 2 + j}


def _legend_right(ax) -> None:
    """The legend right of the axes, level with its top, so it hides no data."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)


def label(text: str) -> str:
    """Plain text for matplotlib (no mathtext from a spec name)."""
    return str(text).replace("$", r"\$")


def _save(fig, path: Path) -> None:
    # Every figure lays itself out (constrained layout, legends beside the axes included), so
    # no bbox_inches="tight": that draws each figure twice (a quarter of the reports' time).
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def draw_or_why(draw: Callable[[Path], str | None], path: Path) -> str | None:
    """Draw one figure into ``path`` (in a worker of the report, which imports only this
    module); why it was left out (the drawing's own reason or a bad input), or None."""
    try:
        return draw(path)
    except (LogError, OSError, KeyError, ValueError) as exc:
        return f"{type(exc).__name__}: {exc}"


def _cols(run: RunData, cols: list[str]) -> dict[str, np.ndarray]:
    return run.log.columns(cols)


def _rings(r: RunData) -> bool:
    """Whether a run's record says some damping mode rings in its data (eq. 36)."""
    p = getattr(r.record, "prediction", None)
    return bool(p is not None and any(j.measured.rings for j in p.modes))


def rates(runs: list[RunData], path: Path, styles: dict[str, RunStyle] | None = None) -> None:
    """‖ω_b‖ over the mission on a log scale, for the runs in which a mode rings (top; all
    runs when none does); below, one row per run (small multiples, so no run hides another):
    the bus yaw rate ω_b,z and the camera roll rate over the last second of each run, against
    the time before its end (missions of different lengths line up), on scales shared by
    column so amplitudes compare, each panel titled with its peak-to-peak amplitude."""
    styles = _styles(runs, styles)
    n = len(runs)
    fig = plt.figure(figsize=(10, 3.4 + 1.2 * n), layout="constrained")
    upper, lower = fig.subfigures(2, 1, height_ratios=[3.4, 1.2 * n])
    top = upper.subplots()
    cols = [_cols(r, ["t", "v_breve"]) for r in runs]
    ringing = [i for i, r in enumerate(runs) if _rings(r)] or list(range(n))
    for j, i in enumerate(ringing):
        r, c = runs[i], cols[i]
        w = np.linalg.norm(c["v_breve"][:, BREVE.omega_b], axis=1)
        top.semilogy(c["t"], np.where(w > 0, w, np.nan), label=label(r.name),
                     **_line_kw(styles[r.name], j, len(ringing), len(w)))
    top.set(title="bus angular rate ‖ω_b‖ (log scale) of the runs in which a mode rings",
            xlabel="t (s)", ylabel="‖ω_b‖ (rad/s)")
    _legend_right(top)
    axes = lower.subplots(n, 2, sharex=True, sharey="col", squeeze=False)
    lower.suptitle("the last second of each run, one row per run: bus yaw rate ω_b,z = v̆[2] "
                   "(left) and camera roll rate ω_e,z = v̆[8] (right)", fontsize=9)
    for i, (r, c) in enumerate(zip(runs, cols, strict=True)):
        last = c["t"] >= c["t"][-1] - 1.0
        st = styles[r.name]
        for k, (idx, what) in enumerate(((2, "ω_b,z"), (8, "ω_e,z"))):
            ax, y = axes[i, k], c["v_breve"][last, idx]
            ax.plot(c["t"][last] - c["t"][-1], y, color=st.color, lw=0.8, marker=".", ms=2.5)
            ax.set_title(label(f"{r.name}: {what}, peak-to-peak {np.ptp(y):.2g} rad/s"),
                         fontsize=8, loc="left", color=st.color)
            ax.set_ylabel(f"{what} (rad/s)")
        for ax in axes[i]:
            ax.set_xlabel("time before the end (s)" if i == n - 1 else "")
    _save(fig, path)


def divergence_growth(run: RunData, path: Path) -> None:
    """|Δω_b| per step of a diverged run on a log scale, with the fitted and the predicted
    growth (eqs. 22, 23)."""
    g = run.record.divergence
    c = _cols(run, ["v_breve"])
    x = c["v_breve"][:, BREVE.omega_b] @ np.array(g.direction)
    d = np.abs(np.diff(x))
    k = np.arange(d.size)
    fig, ax = plt.subplots(figsize=(7, 3.8), layout="constrained")
    ax.semilogy(k, np.maximum(d, 1e-300), "o-", ms=4, lw=0.8, color="0.3",
                label="|x_{k+1} − x_k|, x = ω_b along its step direction")
    k0, k1 = g.fit_steps
    ref = d[k0]
    kk = np.arange(k0, k1)
    for factor, style, what in ((g.predicted, "--", "Φ, simulator's update order"),
                                (g.predicted_note_order, ":", "Φ, the note's update order")):
        ax.semilogy(kk, ref * abs(factor) ** (kk - k0), style, lw=1.2,
                    label=f"{what}: ×{abs(factor):.4g} per step")
    ax.axvline(g.first_limit_step, color="r", lw=0.8,
               label=f"first limit flag (step {g.first_limit_step})")
    ax.set(title=label(f"{run.name}: growth per step {g.growth_factor:+.4g} (measured)"),
           xlabel="step k", ylabel="|Δω_b| per step (rad/s)")
    ax.legend(loc="upper left")
    _save(fig, path)


def lag1_directions(runs: list[RunData], path: Path,
                    styles: dict[str, RunStyle] | None = None) -> None:
    """Lag-1 autocorrelation of each singular direction of Γ (eq. 26), one row per run, its
    value written in its cell and the dominant direction framed: readable for any number of
    runs (bars side by side were not, past four)."""
    n_dir = max((len(r.record.directions) for r in runs), default=0)
    grid = np.full((len(runs), n_dir), np.nan)
    for j, r in enumerate(runs):
        d = r.record.directions
        grid[j, :len(d)] = [np.nan if e.lag1 is None else e.lag1 for e in d]
    fig, ax = plt.subplots(figsize=(9, 1.2 + 0.42 * len(runs)), layout="constrained")
    im = ax.imshow(grid, cmap="RdBu", vmin=-1.0, vmax=1.0, aspect="auto")
    for j, r in enumerate(runs):
        for i in range(n_dir):
            if np.isfinite(grid[j, i]):
                ax.text(i, j, f"{grid[j, i]:+.2f}", ha="center", va="center", fontsize=8,
                        color="w" if abs(grid[j, i]) > 0.6 else "k")
        dom = r.record.dominant.index
        ax.add_patch(plt.Rectangle((dom - 0.5, j - 0.5), 1, 1, fill=False, lw=2.0, ec="k"))
    ax.set_yticks(range(len(runs)), [label(r.name) for r in runs])
    ax.set_xticks(range(n_dir))
    ax.grid(False)
    ax.set(title="lag-1 autocorrelation per direction (framed: the dominant one)",
           xlabel="direction i, singular values descending (index)", ylabel="run")
    fig.colorbar(im, ax=ax, label=f"lag-1 r₁ ({DIMLESS})", shrink=0.9)
    _save(fig, path)


def flown_words(th) -> str:
    """The loop as flown, in a few words: its plant and delay (eq. 34)."""
    late = f", {th.delay_steps} step of delay" if th.delay_steps else ""
    return f"{th.plant} plant{late}"


def eigenvalues(run: RunData, path: Path) -> None:
    """Eigenvalues of the map of the loop as flown (eq. 34: the run's plant and delay) for
    both integrators, against the unit circle."""
    th = run.record.theory
    fig, ax = plt.subplots(figsize=(5, 5), layout="constrained")
    t = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(t), np.sin(t), "k-", lw=0.8, label="unit circle")
    # Black and grey: here the marks are the integrators, and the colours of the runs (the
    # palette) would say "another run".
    for integ, mk, col in (("explicit", "x", "k"), ("imex", "o", "0.5")):
        spectrum = getattr(th.maps, integ)
        ev = spectrum.eigenvalues
        ax.plot(ev.real, ev.imag, mk, color=col, mfc="none", ms=7,
                label=f"{integ}: ρ = {spectrum.spectral_radius:.4g}")
    lim = max(1.2, 1.1 * max(th.maps.explicit.spectral_radius, th.maps.imex.spectral_radius))
    ax.set(xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal", xlabel=f"Re λ ({DIMLESS})",
           ylabel=f"Im λ ({DIMLESS})",
           title=label(f"Φ as flown ({flown_words(th)}) at step {th.step} of {run.name} "
                       f"(dt {th.dt:g} s)"))
    ax.legend(loc="lower left")
    _save(fig, path)


def mode_margins(run: RunData, path: Path) -> None:
    """The fastest damping mode's loop as flown (eq. 35), L(z) = g z^−d/(z − 1) on the unit
    circle (a Nyquist plot, left) with its gain and phase margins marked against −1, and the
    closed-loop roots of every mode's loop in the z-plane (right)."""
    from pipeline.sim.margins import characteristic

    th = run.record.theory
    fast = th.modes[0]
    g, d, m = fast.loop_gain, th.delay_steps, fast.margins
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 5), layout="constrained")
    w = np.linspace(1e-3, np.pi, 2000)
    z = np.exp(1j * w)
    L = g * z ** (-d) / (z - 1.0)
    t = np.linspace(0, 2 * np.pi, 400)
    for ax in (a1, a2):
        ax.plot(np.cos(t), np.sin(t), "-", lw=0.6, color="0.5")
    a1.plot(L.real, L.imag, "-", color="tab:blue", label="L(e^jω), 0 < ω ≤ π")
    a1.plot(L.real, -L.imag, ":", color="tab:blue", lw=0.8)
    a1.plot([-1], [0], "k+", ms=12, mew=2, label="−1")
    L180 = g * np.exp(-1j * d * m.phase_crossover) / (np.exp(1j * m.phase_crossover) - 1.0)
    a1.plot(L180.real, L180.imag, "o", color="tab:red",
            label=f"phase crossover: GM {m.gain_margin_db:.3g} dB")
    if m.gain_crossover is not None:
        zc = np.exp(1j * m.gain_crossover)
        Lc = g * zc ** (-d) / (zc - 1.0)
        a1.plot(Lc.real, Lc.imag, "s", color="tab:green",
                label=f"gain crossover: PM {m.phase_margin_deg:.3g}°")
    lim = max(2.0, 1.2 * abs(L180.real))
    a1.set(xlim=(-lim, 1.0), ylim=(-lim, lim), aspect="equal", xlabel=f"Re L ({DIMLESS})",
           ylabel=f"Im L ({DIMLESS})",
           title=label(f"{fast.symbol} loop as flown ({flown_words(th)}), g = {g:.3g}"))
    a1.legend(loc="lower left", fontsize=LEGEND_MIN_PT)
    for i, mode in enumerate(th.modes):
        roots = np.roots(characteristic(mode.loop_gain, d))
        a2.plot(roots.real, roots.imag, "x" if i else "*", ms=12 if i == 0 else 6,
                color="tab:red" if i == 0 else "0.35",
                label=f"{mode.symbol} (fastest), |z| {mode.modulus:.3g}" if i == 0 else
                ("the other modes" if i == 1 else None))
    rmax = max(1.2, 1.1 * max(mode.modulus for mode in th.modes))
    a2.set(xlim=(-rmax, rmax), ylim=(-rmax, rmax), aspect="equal", xlabel=f"Re z ({DIMLESS})",
           ylabel=f"Im z ({DIMLESS})", title=label("Roots of each mode's loop as flown"))
    a2.legend(loc="lower left", fontsize=LEGEND_MIN_PT)
    _save(fig, path)


def gamma_ramp(runs: list[RunData], path: Path,
               styles: dict[str, RunStyle] | None = None) -> None:
    """The γ ramp of the spec's conditioning knobs with the logged (s_min_G, γ) of each run
    (top); the runs' points lie on one curve and cover each other there, so below, one strip
    per run shows where along σ_min(Γ) its steps were."""
    styles = _styles(runs, styles)
    n = len(runs)
    fig, (ax, strips) = plt.subplots(2, 1, figsize=(9.5, 3.6 + 0.3 * n), sharex=True,
                                     height_ratios=[3.2, 0.3 * n + 0.4], layout="constrained")
    knobs = None
    smax = 0.0
    for i, r in enumerate(runs):
        c = _cols(r, ["s_min_G", "gamma"])
        st = styles[r.name]
        # Every 10th step: enough to show the cloud, few enough to leave the others visible.
        ax.plot(c["s_min_G"][::10], c["gamma"][::10], st.marker, color=st.color, ms=4,
                mfc="none", alpha=0.8, label=label(r.name))
        strips.plot(c["s_min_G"][::10], np.full(c["s_min_G"][::10].size, i), "|",
                    color=st.color, ms=8)
        knobs = knobs or r.conditioning
        smax = max(smax, float(c["s_min_G"].max()))
    low, high, floor = knobs or (0.01, 0.05, 0.3)
    s = np.linspace(0, max(high * 2, 1.1 * smax), 500)
    ax.plot(s, [scale_by_svd(x, low, high, floor) for x in s], "k-", lw=1.2, zorder=1,
            label=f"scale_by_svd (low {low:g}, high {high:g}, floor {floor:g})")
    ax.set(title="γ ramp and the logged s_min_G (every 10th step)", ylabel=f"γ ({DIMLESS})",
           ylim=(0, 1.08))
    _legend_right(ax)
    strips.set_yticks(range(n), [label(r.name) for r in runs], fontsize=8)
    strips.set(ylim=(n - 0.5, -0.5), xlabel="σ_min(Γ) (SI mixed)", ylabel="run")
    for ax_ in (ax, strips):
        for x in (low, high):
            ax_.axvline(x, color="0.5", lw=0.6, ls=":")
    _save(fig, path)


def conditioning(runs: list[RunData], path: Path,
                 styles: dict[str, RunStyle] | None = None) -> None:
    """σ_min(Γ), σ_min(J⊕) and κ(Γ) per step, one panel each, one legend for all."""
    styles = _styles(runs, styles)
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True, layout="constrained")
    n = len(runs)
    for j, r in enumerate(runs):
        c = _cols(r, ["t", "s_min_G", "s_min_J", "kappa_G"])
        kw = _line_kw(styles[r.name], j, n, len(c["t"]))
        axes[0].plot(c["t"], c["s_min_G"], label=label(r.name), **kw)
        axes[1].plot(c["t"], c["s_min_J"], **kw)
        axes[2].semilogy(c["t"], c["kappa_G"], **kw)
    axes[0].set(title="conditioning over the mission", ylabel="σ_min(Γ) (SI mixed)")
    axes[1].set(ylabel="σ_min(J⊕) (SI mixed)")
    axes[2].set(ylabel=f"κ(Γ) ({DIMLESS})")
    for ax in axes:
        ax.set_xlabel("t (s)")
    _legend_right(axes[0])
    _save(fig, path)


def _delay(run: RunData) -> int:
    """The computation delay the run flew, in steps (0 on the simulator's update)."""
    return int(getattr(getattr(run.record, "theory", None), "delay_steps", 0) or 0)


def dt_mu(runs: list[RunData], path: Path, styles: dict[str, RunStyle] | None = None) -> None:
    """The online guard's dt·μ_max per step; runs of one robot and dt coincide, so each is
    drawn in its own line style and width with staggered markers."""
    from pipeline.sim.margins import gain_margin

    styles = _styles(runs, styles)
    n = len(runs)
    # Tall enough for its legend (one line per run): a legend taller than the axes collapses
    # the constrained layout.
    fig, ax = plt.subplots(figsize=(8, max(3.6, 0.8 + 0.19 * (n + 2))), layout="constrained")
    for j, r in enumerate(runs):
        c = _cols(r, ["t", "dt_mu_max"])
        ax.plot(c["t"], c["dt_mu_max"],
                label=label(f"{r.name} ({r.record.integrator})"),
                **_line_kw(styles[r.name], j, n, len(c["t"])))
    # Forward Euler's bound on each delay flown (eq. 35: 2 without delay, 1 with one step).
    for d, ls in zip(sorted({_delay(r) for r in runs}), ("--", ":", "-."), strict=False):
        b = gain_margin(1.0, d)[0]
        ax.axhline(b, color="k", lw=1.0, ls=ls,
                   label=f"{b:.3g}: forward Euler's bound, {d} step(s) of delay")
    ax.set(title="dt·μ_max over the mission", xlabel="t (s)",
           ylabel=f"dt·μ_max ({DIMLESS})", ylim=(0, None))
    _legend_right(ax)
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
    a_max = _omega_b_acc_bound(df)
    amp = "bus_rate_alternating_rms" in df and a_max is not None
    fig, axes = plt.subplots(1, 3 if amp else 2, figsize=(13.5 if amp else 9, 3.8),
                             layout="constrained")
    a1, a2 = axes[0], axes[1]
    unstable = df["dt_mu_max"] > 2
    for ax, col, ttl, ylab in ((a1, lag, "dominant lag-1", f"lag-1 r₁ ({DIMLESS})"),
                               (a2, "dt_mu_max", "dt·μ_max", f"dt·μ_max ({DIMLESS})")):
        ax.plot(df["mission.dt"], df[col], "-", color="0.6", lw=0.8)
        ax.plot(df["mission.dt"][~unstable], df[col][~unstable], "o", color="tab:green",
                label="dt·μ_max < 2")
        ax.plot(df["mission.dt"][unstable], df[col][unstable], "s", color="tab:red",
                label="dt·μ_max > 2")
        if "dt_star_damping" in df and df["dt_star_damping"].notna().any():
            ax.axvline(float(df["dt_star_damping"].median()), color="k", ls="--", lw=0.8,
                       label=f"dt*_damping = {float(df['dt_star_damping'].median()):.4g} s")
        ax.set(title=ttl, xlabel="mission.dt (s)", ylabel=ylab)
        ax.xaxis.set_major_locator(MaxNLocator(6))  # dt ticks of 4 digits collide otherwise
    a2.axhline(2.0, color="r", lw=0.8)
    a1.legend()
    if amp:
        # The ripple's size: a cycle held by the acceleration bound moves ω_b by dt·a_max per
        # step, so its alternating part has amplitude dt·a_max/2 (eq. 16).
        a3, dt = axes[2], df["mission.dt"]
        y = df["bus_rate_alternating_rms"].clip(lower=1e-16)
        a3.semilogy(dt[~unstable], y[~unstable], "o", color="tab:green", label="dt·μ_max < 2")
        a3.semilogy(dt[unstable], y[unstable], "s", color="tab:red", label="dt·μ_max > 2")
        grid = np.linspace(float(dt.min()), float(dt.max()), 100)
        a3.semilogy(grid, grid * a_max / 2, "k--", lw=0.9,
                    label=f"dt·a_max/2, a_max = {a_max:.4g} rad/s²")
        a3.set(title="ω_b period-2 amplitude", xlabel="mission.dt (s)", ylabel="RMS (rad/s)")
        a3.xaxis.set_major_locator(MaxNLocator(6))
        a3.legend(loc="lower right")
    fig.suptitle(label(f"dt sweep {table.parent.name}"))
    _save(fig, path)
    return None


def _omega_b_acc_bound(df: pd.DataFrame) -> float | None:
    """The ω_b acceleration bound of a sweep's points (their specs', read from a log's
    metadata), or None when no log is readable or the points differ in it."""
    from pipeline.errors import PipelineError
    from pipeline.store.door import ArtefactStore

    store = ArtefactStore()
    bounds = set()
    for log in df.get("log", pd.Series(dtype=str)).dropna():
        try:
            bounds.add(float(store.open_log(log).spec.controller.limits.omega_b_acc))
        except (PipelineError, OSError):
            return None
    return bounds.pop() if len(bounds) == 1 else None


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
    df = df[df["status"] == "complete"].dropna(subset=need[:3]).sort_values("I_zz_bus")
    if df.empty:
        return f"{table}: no complete point"
    # None where no crossing was found for a point (the bus-yaw mode off its closed form).
    crit = float(df["bus_critical_I_zz"].dropna().median())
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
    ring = df["bus_rate_lag1"] < 0
    for ax, col, ttl, ylab in (
            (a1, "bus_rate_lag1", "lag-1 of ω_b's dominant step component",
             f"lag-1 r₁ ({DIMLESS})"),
            (a2, "bus_rate_alternating_rms", "ω_b period-2 amplitude", "RMS (rad/s)")):
        ax.plot(df["I_zz_bus"], df[col], "-", color="0.6", lw=0.8)
        ax.plot(df["I_zz_bus"][ring], df[col][ring], "s", color="tab:red", label="r₁ < 0")
        ax.plot(df["I_zz_bus"][~ring], df[col][~ring], "o", color="tab:green", label="r₁ ≥ 0")
        if np.isfinite(crit):
            ax.axvline(crit, color="k", ls="--", lw=0.8,
                       label=f"predicted I_zz,bus at dt·μ_bus = 2: {crit:.4g} kg·m²")
        ax.set_xscale("log")
        ax.set(title=ttl, xlabel="I_zz,bus (kg·m²)", ylabel=ylab)
    a2.set_yscale("log")
    a1.set_ylim(-1.05, 1.05)
    a1.legend(loc="center right")
    fig.suptitle(label(f"bus-inertia sweep {table.parent.name}"))
    _save(fig, path)
    return None


def _short(name: str) -> str:
    """A run's name without the shipped missions' common prefix, for a label on a point."""
    return name.removeprefix("omega_ripple_")


def stability_region(runs: list[RunData], tables: list[Path], path: Path,
                     styles: dict[str, RunStyle] | None = None) -> None:
    """Left: the (dt, μ) plane of one damping mode (eqs. 23, 24, 35), unstable above dt·μ = 2
    without delay and above dt·μ = 1 with one step of it; each run's fastest mode, marked by
    its loop (explicit, explicit with one step of delay, imex) and labelled by name (runs at
    one point share a label), and every sweep point (μ_max at its dt) by its measured lag-1.
    Right: the eigenvalues of the map as flown (eq. 34) as dt varies, one locus per robot and
    loop (its explicit run of the largest step), against the unit circle; at most eight key
    entries a panel."""
    from pipeline.sim.stability import flown_map

    st = _styles(runs, styles)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(13, 6.2), layout="constrained",
                                 width_ratios=[1.15, 1])
    dts = np.geomspace(1e-3, 0.1, 200)
    mus = np.array([1e-2, 1e4])
    a1.fill_between(dts, 2 / dts, mus[1], color="tab:red", alpha=0.12,
                    label="dt·μ > 2: unstable (no delay)")
    a1.fill_between(dts, 1 / dts, 2 / dts, color="tab:orange", alpha=0.12,
                    label="1 < dt·μ < 2: rings; unstable with one step of delay")
    a1.fill_between(dts, mus[0], 1 / dts, color="tab:green", alpha=0.10,
                    label="dt·μ ≤ 1: stable with one step of delay")
    a1.plot(dts, 2 / dts, "r-", lw=1.0)
    a1.plot(dts, 1 / dts, "k--", lw=0.9)
    ring_pts, calm_pts = [], []
    for table in tables:
        df = pd.read_parquet(table)
        need = ["dt_mu_max", "mu_max", "dominant_lag1"]
        if any(c not in df for c in need):
            continue
        df = df[df["status"] == "complete"].dropna(subset=need)
        dt_pt = df["dt_mu_max"] / df["mu_max"]
        ring = (df["dominant_lag1"] < 0).to_numpy()
        ring_pts.append((dt_pt[ring], df["mu_max"][ring]))
        calm_pts.append((dt_pt[~ring], df["mu_max"][~ring]))
    for pts, mk, col, text in ((ring_pts, "s", "tab:red", "sweep point, lag-1 < 0"),
                               (calm_pts, "o", "tab:green", "sweep point, lag-1 ≥ 0")):
        for i, (x, y) in enumerate(pts):
            a1.plot(x, y, mk, ms=4, mfc="none", color=col, label=text if i == 0 else None)
    # Runs whose fastest mode sits at one point of the plane share a mark and a label.
    groups: dict[tuple, list[RunData]] = {}
    for r in runs:
        th = r.record.theory
        key = (th.dt, round(th.fastest_mode.mu, 6), th.integrator, th.delay_steps)
        groups.setdefault(key, []).append(r)
    kinds = {("explicit", False): ("*", "explicit, no delay"),
             ("explicit", True): ("D", "explicit, one step of delay"),
             ("imex", False): ("P", "imex"), ("imex", True): ("P", "imex")}
    keyed: set[str] = set()
    # Labels of points on one row (one μ, the seed's bus yaw at many steps) are staggered up
    # and down, so that neighbours do not print over each other.
    row: dict[float, int] = {}
    for (dt, mu, integ, delay), members in sorted(groups.items()):
        mk, kind = kinds[(integ, bool(delay))]
        a1.plot(dt, mu, mk, ms=10, color="0.2", mfc="none" if integ == "imex" else "0.2",
                label=None if kind in keyed else kind)
        keyed.add(kind)
        i = row[mu] = row.get(mu, -1) + 1
        a1.annotate(", ".join(_short(m.name) for m in members), (dt, mu), fontsize=7,
                    xytext=(4, (8 + 10 * (i // 2)) * (1 if i % 2 == 0 else -1.6)),
                    textcoords="offset points", rotation=20)
    t = np.linspace(0, 2 * np.pi, 400)
    a2.plot(np.cos(t), np.sin(t), "k-", lw=0.8)
    locus_dts = np.geomspace(0.002, 0.05, 60)
    loops: dict[tuple, RunData] = {}
    for r in runs:
        th = r.record.theory
        if th.integrator != "explicit":
            continue
        key = (str(r.spec.get("robot", {}).get("file", "?")), th.plant, th.delay_steps)
        if key not in loops or th.dt > loops[key].record.theory.dt:
            loops[key] = r
    for r in loops.values():
        th = r.record.theory
        M, D, K_x, J_x = (np.asarray(m) for m in (th.M_breve, th.D_breve, th.K_x, th.J_x))
        ev = np.array([np.linalg.eigvals(flown_map(M, D, K_x, J_x, dt, "explicit", th.plant,
                                                   th.delay_steps)) for dt in locus_dts])
        a2.scatter(ev.real.ravel(), ev.imag.ravel(), s=4, c=np.repeat(locus_dts, ev.shape[1]),
                   cmap="viridis", norm=matplotlib.colors.LogNorm())
        here = np.linalg.eigvals(flown_map(M, D, K_x, J_x, th.dt, "explicit", th.plant,
                                           th.delay_steps))
        a2.plot(here.real, here.imag, "x", ms=8, color=st[r.name].color,
                label=f"{r.name} ({flown_words(th)}, dt = {th.dt:g} s)")
    a1.set(xscale="log", yscale="log", xlim=(dts[0], dts[-1]), ylim=(10.0, 1e3),
           xlabel="dt (s)", ylabel="μ of the mode (1/s)",
           title=label("Stability of one damping mode, each run's fastest"))
    a1.legend(loc="lower left", fontsize=LEGEND_MIN_PT)
    sm = plt.cm.ScalarMappable(cmap="viridis", norm=matplotlib.colors.LogNorm(
        locus_dts[0], locus_dts[-1]))
    fig.colorbar(sm, ax=a2, label="dt (s)")
    a2.set(xlim=(-4, 1.5), ylim=(-2.2, 2.2), xlabel=f"Re λ ({DIMLESS})",
           ylabel=f"Im λ ({DIMLESS})",
           title=label("Eigenvalues of Φ as flown (explicit) as dt varies"))
    a2.set_aspect("equal", adjustable="box")
    a2.legend(loc="lower left", fontsize=LEGEND_MIN_PT)
    _save(fig, path)


def against_log(run: RunData) -> VerifiedLog | None:
    """The log of the run ``run`` is compared with, when both logs are there as analysed
    (the pair's figures need them), else None."""
    return run.against if run.log is not None else None


def _pair_series(run: RunData, against: VerifiedLog, styles: dict[str, RunStyle] | None
                 ) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(name, colour, t, x) of a run and of the run it is compared with, x the fastest damping
    mode's reduced coordinate (eq. 21), each log read once; each run in its report colour."""
    axis = run.record.theory.fastest_mode.axis
    other = run.record.comparison.against
    st = styles or palette([run.name, other])
    out = []
    for name, log, color in ((run.name, run.log, st[run.name].color),
                             (other, against, st[other].color if other in st else "0.45")):
        c = log.columns(["t", "v_breve"])
        out.append((name, color, c["t"], c["v_breve"][:, axis]))
    return out


def startup_growth(run: RunData, against: VerifiedLog, path: Path,
                   styles: dict[str, RunStyle] | None = None) -> None:
    """The fastest damping mode's reduced coordinate (eq. 21) over the first half-second of a
    run and of the run it is compared with (top), and the size of its alternating part,
    a_k = |x_k − 2x_{k+1} + x_{k+2}|/4 (bottom, log scale), against the growth |λ|^k that Φ's
    dominant eigenvalue predicts (eq. 22) until the saturation holds it."""
    th = run.record.theory
    axis, name = th.fastest_mode.axis, th.fastest_mode.name
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), layout="constrained", sharex=True)
    series = _pair_series(run, against, styles)
    for label_, color, t_all, x_all in series:
        keep = t_all <= 0.5
        t, x = t_all[keep], x_all[keep]
        a1.plot(t, x, "-o", ms=3, lw=0.9, color=color, label=label_)
        alt = np.abs(x[:-2] - 2 * x[1:-1] + x[2:]) / 4
        a2.semilogy(t[:-2], np.maximum(alt, 1e-18), "o", ms=3, color=color, label=label_)
    if th.integrator == "explicit":
        _, _, t, x = series[0]
        alt = np.abs(x[:-2] - 2 * x[1:-1] + x[2:]) / 4
        lam = abs(complex(th.eig_dominant.real, th.eig_dominant.imag))
        k0 = int(np.argmax(alt > 0))
        k = np.arange(k0, min(len(alt), k0 + 12))
        a2.semilogy(t[k], alt[k0] * lam ** (k - k0), "k--", lw=0.9,
                    label=f"|λ_dom|^k = {lam:.3g}^k (Φ's dominant eigenvalue)")
    a1.set(ylabel=f"{axis_symbol(axis)} (rad/s)",
           title=label(f"{name} over the first half-second"))
    a2.set(xlabel="t (s)", ylabel="alternating part (rad/s)", ylim=(1e-8, 1.0))
    a1.legend(loc="upper left")
    a2.legend(loc="lower right")
    _save(fig, path)


def mode_psd(run: RunData, against: VerifiedLog, path: Path,
             styles: dict[str, RunStyle] | None = None) -> None:
    """The power spectral density (Welch, SciPy) of the fastest damping mode's reduced
    coordinate over the analysis window (the second half) of a run and of the run it is
    compared with, each with its Nyquist frequency 1/(2 dt): a period-2 ripple is a peak at
    it."""
    from scipy.signal import welch

    th = run.record.theory
    axis, name = th.fastest_mode.axis, th.fastest_mode.name
    fig, ax = plt.subplots(figsize=(7, 3.8), layout="constrained")
    for label_, color, t, x in _pair_series(run, against, styles):
        x = x[len(x) // 2:]
        dt = float(t[1] - t[0])
        f, p = welch(x - x.mean(), fs=1.0 / dt, nperseg=min(256, len(x)))
        ax.loglog(f[1:], np.maximum(p[1:], 1e-30), "-", lw=1.0, color=color, label=label_)
        ax.axvline(0.5 / dt, color=color, ls="--", lw=0.9,
                   label=f"Nyquist of {label_}: 1/(2·{dt:g} s) = {0.5 / dt:.3g} Hz")
    ax.set(xlabel="frequency (Hz)", ylabel=f"PSD of {axis_symbol(axis)} (rad²/s²/Hz)",
           title=label(f"{name} over the window: power spectral density"))
    ax.legend(loc="lower left")
    _save(fig, path)
