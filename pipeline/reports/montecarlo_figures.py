"""The Monte Carlo's figures (eqs. 38, 39), from its table: the ECDF of each sample's least
gain margin against the requirement, each margin against each dispersed parameter, and the
pass/fail map over the two parameters the gain margin follows most."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import scipy.stats

from pipeline.montecarlo.verdict import DRAW, draw_keys, read_table, read_verdict
from pipeline.reports.figures import DIMLESS, _save, label, plt

PASS, FAIL = "tab:blue", "tab:red"
MARGINS = (("gain_margin_db", "least gain margin (dB)", "gain_margin_db"),
           ("phase_margin_deg", "least phase margin (°)", "phase_margin_deg"),
           ("delay_margin_steps", "least delay margin (steps)", "delay_margin_steps"))


def _finite(df: pd.DataFrame, col: str) -> pd.Series:
    return df[col].astype(float).replace([np.inf, -np.inf], np.nan)


def ecdf(table: Path, path: Path) -> str | None:
    """The ECDF of the least gain margin over the samples, the requirement's line, and the
    fraction below it."""
    df, v = read_table(table), read_verdict(table.parent / "verdict.json")
    gm = _finite(df, "gain_margin_db").dropna().sort_values()
    if gm.empty:
        return f"{table}: no sample with a gain margin (no run completed)"
    fig, ax = plt.subplots(figsize=(7.5, 3.8), layout="constrained")
    y = np.arange(1, len(gm) + 1) / len(df)
    ax.step(gm.to_numpy(), y, where="post", color="k", lw=1.2, label="samples (ECDF)")
    req = v.requirement.gain_margin_db
    below = float((gm < req).sum()) / len(df)
    ax.axvline(req, color=FAIL, ls="--", lw=1.0,
               label=f"requirement {req:g} dB ({100 * below:.2f} % of samples below)")
    ax.set(xlabel="least gain margin over the damping modes (dB)",
           ylabel=f"fraction of samples ({DIMLESS})",
           title=label(f"Monte Carlo {v.name}: {v.samples} samples"))
    ax.legend(loc="lower right")
    _save(fig, path)
    return None


def parameters(table: Path, path: Path) -> str | None:
    """Each margin (rows) against each dispersed parameter (columns), passing samples blue
    and failing red, the requirement dashed."""
    df, v = read_table(table), read_verdict(table.parent / "verdict.json")
    keys = draw_keys(df)
    if not keys:
        return f"{table}: no dispersed parameter varies"
    req = {"gain_margin_db": v.requirement.gain_margin_db,
           "phase_margin_deg": v.requirement.phase_margin_deg,
           "delay_margin_steps": v.requirement.delay_margin_steps}
    ok = df["passes"].astype(bool)
    fig, axes = plt.subplots(len(MARGINS), len(keys), figsize=(2.9 * len(keys) + 1, 7.5),
                             layout="constrained", squeeze=False)
    for j, key in enumerate(keys):
        x = df[DRAW + key].astype(float)
        for i, (col, name, rkey) in enumerate(MARGINS):
            ax = axes[i, j]
            y = _finite(df, col)
            ax.plot(x[ok], y[ok], ".", color=PASS, ms=3, label="passes")
            ax.plot(x[~ok], y[~ok], "x", color=FAIL, ms=4, label="fails")
            ax.axhline(req[rkey], color=FAIL, ls="--", lw=0.8)
            if i == len(MARGINS) - 1:
                ax.set_xlabel(label(key), fontsize=8)
            if j == 0:
                ax.set_ylabel(name)
    axes[0, 0].legend(loc="best")
    fig.suptitle(label(f"Monte Carlo {v.name}: margins against each dispersed parameter "
                       f"(dashed: the requirement)"))
    _save(fig, path)
    return None


def strongest(df: pd.DataFrame, keys: list[str]) -> list[str]:
    """The dispersed parameters by the strength of their rank correlation with the least gain
    margin (Spearman's |ρ|, SciPy's), strongest first."""
    gm = _finite(df, "gain_margin_db")
    keep = gm.notna()

    def strength(key: str) -> float:
        r = scipy.stats.spearmanr(df[DRAW + key][keep], gm[keep]).statistic
        return 0.0 if not np.isfinite(r) else abs(float(r))

    return sorted(keys, key=strength, reverse=True)


def pass_fail_map(table: Path, path: Path) -> str | None:
    """Pass (blue) and fail (red) over the two dispersed parameters the least gain margin
    follows most."""
    df, v = read_table(table), read_verdict(table.parent / "verdict.json")
    keys = strongest(df, draw_keys(df))
    if len(keys) < 2:
        return f"{table}: fewer than two dispersed parameters vary"
    a, b = keys[:2]
    ok = df["passes"].astype(bool)
    fig, ax = plt.subplots(figsize=(6.5, 4.6), layout="constrained")
    ax.plot(df[DRAW + a][ok], df[DRAW + b][ok], ".", color=PASS, ms=4,
            label=f"passes ({int(ok.sum())})")
    ax.plot(df[DRAW + a][~ok], df[DRAW + b][~ok], "x", color=FAIL, ms=6,
            label=f"fails ({int((~ok).sum())})")
    ax.set(xlabel=label(a), ylabel=label(b),
           title=label(f"Monte Carlo {v.name}: pass/fail over the two parameters the least "
                       "gain margin follows most"))
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    _save(fig, path)
    return None


def detector_power(result: Path, path: Path) -> str | None:
    """False-alarm and missed-detection rates of both detectors against the noise level (log
    axis, level 0 drawn at the left edge), and the ringing mission's ripple amplitude."""
    from pipeline.montecarlo.power import DETECTORS, read_power

    r = read_power(result)
    levels = np.array([x.level for x in r.levels])
    positive = levels[levels > 0]
    if positive.size < 2:
        return f"{result}: fewer than two positive noise levels"
    floor = positive.min() / 3  # where level 0 is drawn
    x = np.where(levels > 0, levels, floor)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(13, 4.2), layout="constrained",
                                 width_ratios=(1.6, 1))
    styles = {"lag1": ("tab:purple", "o"), "spectral": ("tab:green", "s")}
    for d in DETECTORS:
        color, marker = styles[d]
        a1.semilogx(x, [100 * v.missed[d] for v in r.levels], "-" + marker, color=color,
                    label=f"{d}: missed detections (ripple mission)")
        a1.semilogx(x, [100 * v.false_alarm[d] for v in r.levels], "--" + marker, color=color,
                    mfc="none", label=f"{d}: false alarms (quiet mission)")
        if r.crossing[d] is not None:
            a1.axvline(max(r.crossing[d], floor), color=color, lw=0.8, ls=":")
    a1.axhline(50, color="0.5", lw=0.8)
    a1.set(xlabel=label(f"{r.noise} ({r.unit}); level 0 at the left edge"),
           ylabel="rate (%)", ylim=(-3, 103),
           title=label(f"Detectors against {r.noise}, {r.samples} samples per point"))
    a1.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    a2.loglog(x, [max(v.ripple_amplitude, 1e-16) for v in r.levels], "-o", color="k")
    a2.set(xlabel=label(f"{r.noise} ({r.unit})"), ylabel="rad/s",
           title="ω_b period-2 amplitude as measured\n(ripple mission, median)")
    _save(fig, path)
    return None


def least_change(result: Path, path: Path) -> str | None:
    """A search's samples (eq. 43): the fraction of them failing at each value of the knob,
    bounded below by those flown failing at or below it and above by those not yet shown to
    meet it there, with the nominal value, the least change every sample meets and the
    fraction the target allows (1 − p)."""
    from pipeline.montecarlo.sealed import unseal

    data = unseal(Path(result).read_text())
    r = data["search"]
    n = r["samples"]
    passes = np.array([np.nan if b["passes_at"] is None else b["passes_at"]
                       for b in r["brackets"]])
    fails = np.array([np.nan if b["fails_at"] is None else b["fails_at"] for b in r["brackets"]])
    values = np.unique(np.concatenate([passes[np.isfinite(passes)], fails[np.isfinite(fails)]]))
    if values.size == 0:
        return f"{result}: no sample flown"
    lo = np.array([np.sum(fails <= x) for x in values]) / n  # flown failing at or below x
    hi = np.array([np.sum(~(passes >= x)) for x in values]) / n  # not shown to meet x
    fig, ax = plt.subplots(figsize=(7.5, 3.8), layout="constrained")
    ax.step(values, hi, where="post", color=FAIL, lw=1.2,
            label="at most (samples not flown meeting it there)")
    ax.step(values, lo, where="post", color="k", lw=1.2,
            label="at least (samples flown failing there)")
    ax.axvline(r["nominal"], color="0.5", ls=":", lw=1.0, label=f"nominal {r['nominal']:.4g}")
    if r["chosen"] is not None:
        ax.axvline(r["chosen"], color=PASS, ls="--", lw=1.2,
                   label=f"least change every sample meets, {r['chosen']:.4g}")
    ax.axhline(1 - data["target_p"], color="tab:orange", ls="-.", lw=1.0,
               label=f"what the target allows to fail, 1 − p = {1 - data['target_p']:.4g}")
    ax.set(xlabel=f"{data['knob']} ({data['knob_words']})",
           ylabel=f"fraction of samples failing ({DIMLESS})",
           title=label(f"Least change, {data['montecarlo']}: {n} samples, {r['flights']} "
                       "flights"))
    ax.set_yscale("symlog", linthresh=1e-3)  # linear through 0, the target's 1 − p visible
    ax.set_ylim(0.0, 1.0)
    ax.legend(loc="center left", fontsize=8)
    _save(fig, path)
    return None
