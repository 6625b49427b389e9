"""The analysis of one log (DESIGN §3): stages 1–6, and stage 7 for a pair of logs.

Window rule: the analysis window is [window_start, end) with window_start = half the mission
by default, so start-up transients are excluded; theory is evaluated at the representative
step, the step of the window where the logged s_min_G is smallest (closest to singular).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.analysis import signals, theory
from pipeline.analysis.directions import project_chunk, rebuild_gamma
from pipeline.errors import CheckFailed, LogError
from pipeline.logs import iter_columns, num_rows, read_columns, read_meta, require_columns
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.limits import LIMIT_FLAGS
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.svd import batched_singular_values
from pipeline.spec import Spec, SpecError, build_spec

REQUIRED = ["step", "t", "q", "v", "s_min_G", "kappa_G", "x_tilde", "dt_mu_max",
            "pointing_err_deg", "boresight_err_deg", "coverage", *LIMIT_FLAGS]
PROVENANCE_TOL = 1e-10  # same code on the same q: equal up to LAPACK's last bits


@dataclass
class Window:
    start: int
    stop: int
    rule: str


def spec_of_log(path, meta) -> Spec:
    content = {k: v for k, v in meta.spec.items() if k != "name"}
    try:
        return build_spec(meta.spec.get("name", path.parent.name), content, path)
    except SpecError as exc:
        raise LogError(f"{path}: metadata key pipeline.spec is not a valid spec ({exc})") from None


def choose_window(n: int, dt: float, window_start: float | None) -> Window:
    if window_start is None:
        return Window(n // 2, n, "second half of the mission (after start-up transients)")
    start = round(window_start / dt)
    if window_start < 0 or n - start < 3:
        raise LogError(f"window start {window_start} s leaves fewer than 3 steps of a "
                       f"{n * dt:g} s log")
    return Window(start, n, f"from {window_start:g} s to the end")


def analyze_log(path, window_start: float | None = None, check: bool = True) -> dict:
    """All single-log stages; returns the analysis record (the content of analysis.json)."""
    meta = read_meta(path)
    if meta.status != "complete":
        raise LogError(f"{path}: log marked {meta.status} at step {meta.failed_step}: "
                       f"{meta.error}")
    spec = spec_of_log(path, meta)
    require_columns(path, REQUIRED)
    n = num_rows(path)
    dt = spec.mission.dt
    win = choose_window(n, dt, window_start)
    robot = GiordanoRobot(spec)

    # Stages 1 and 2: Γ rebuilt at every step, velocity projected in the window.
    prov, y, sigma = rebuild_and_project(robot, path, win)
    if check and prov["max_abs_s_min_G"] > PROVENANCE_TOL:
        raise CheckFailed(f"{path}: provenance: rebuilt σ_min(Γ) differs from logged s_min_G "
                          f"by {prov['max_abs_s_min_G']:.3e} at step {prov['worst_step']} "
                          f"(tolerance {PROVENANCE_TOL:g})")

    # Stage 3: per-direction statistics and the dominant direction.
    lag1 = signals.lag1_autocorrelation(y)
    srms = signals.step_rms(y)
    dom = int(np.argmax(srms))
    directions = [
        {"direction": i, "sigma": float(np.median(sigma[:, i])), "rms": float(signals.rms(y[:, i])),
         "step_rms": float(srms[i]), "lag1": float(lag1[i])}
        for i in range(y.shape[1])
    ]

    # The window's columns, but not q and x̃: stages 1–4 read those by row group or by step.
    cols = read_columns(path, [c for c in REQUIRED if c not in ("q", "x_tilde", "kappa_G")],
                        win.start, win.stop)
    rep = win.start + int(np.argmin(cols["s_min_G"]))
    th = theory_at_step(robot, spec, path, rep)

    # Stages 5 and 6: alignment of theory and data directions, per-step velocity jump.
    data_dir = signals.dominant_step_direction(cols["v"])
    jumps = signals.velocity_jumps(cols["v"])
    return {
        "spec_name": spec.name, "log": str(path), "spec_hash": meta.spec_hash,
        "code_version": meta.code_version, "integrator": spec.controller.integrator,
        "dt": dt, "n_steps": n,
        "window": {"start_step": win.start, "stop_step": win.stop, "rule": win.rule},
        "provenance": prov,
        "directions": directions,
        "dominant": {"index": dom, "sigma": directions[dom]["sigma"],
                     "lag1": directions[dom]["lag1"], "step_rms": directions[dom]["step_rms"],
                     "step_energy_share": float(srms[dom] ** 2 / np.sum(srms**2))},
        "theory": th["record"],
        "alignment": {"abs_cos": signals.abs_cos(th["direction"], data_dir),
                      "theory_direction": th["direction"].tolist(),
                      "data_direction": data_dir.tolist()},
        "velocity_jump": {"median": float(np.median(jumps)), "max": float(np.max(jumps))},
        "bus_rate": bus_rate_statistics(cols["v"][:, 3:6]),
        "metrics": mission_metrics(cols),
    }


BATCH = 8192  # steps per batched SVD: its ~8 temporaries of 12×12 per step stay near 10 MB


def _batches(chunks, size: int = BATCH):
    """Split each row group's columns into batches of at most ``size`` steps."""
    for chunk in chunks:
        n = len(chunk["step"])
        for lo in range(0, n, size):
            yield {k: a[lo:lo + size] for k, a in chunk.items()}


def rebuild_and_project(robot: GiordanoRobot, path, win: Window
                        ) -> tuple[dict, np.ndarray, np.ndarray]:
    """Stages 1–2, streamed by row group: provenance over every step, and the projections
    y (eq. 26) and singular values of Γ over the window (singular vectors only there)."""
    worst, worst_step, worst_kappa = 0.0, -1, 0.0
    ys, sigmas, V_prev = [], [], None
    for chunk in _batches(iter_columns(path, ["step", "q", "v", "s_min_G", "kappa_G"])):
        gamma = rebuild_gamma(robot, chunk["q"])
        keep = (chunk["step"] >= win.start) & (chunk["step"] < win.stop)
        sigma = np.empty((len(gamma), gamma.shape[1]))
        sigma[~keep] = batched_singular_values(gamma[~keep])
        if keep.any():
            part = project_chunk(gamma[keep], chunk["v"][keep], V_prev)
            V_prev = part.V_last
            sigma[keep] = part.sigma
            ys.append(part.y)
            sigmas.append(part.sigma)
        diff = np.abs(sigma[:, -1] - chunk["s_min_G"])
        if diff.size and diff.max() > worst:
            worst, worst_step = float(diff.max()), int(chunk["step"][np.argmax(diff)])
        rel_k = np.abs(sigma[:, 0] / sigma[:, -1] - chunk["kappa_G"]) / chunk["kappa_G"]
        worst_kappa = max(worst_kappa, float(rel_k.max(initial=0.0)))
    if not ys:
        raise LogError(f"{path}: no row's step lies in the analysis window "
                       f"[{win.start}, {win.stop}): the step column is not 0, 1, …")
    prov = {"max_abs_s_min_G": worst, "worst_step": worst_step, "max_rel_kappa_G": worst_kappa,
            "tolerance": PROVENANCE_TOL}
    return prov, np.concatenate(ys), np.concatenate(sigmas)


def theory_at_step(robot: GiordanoRobot, spec: Spec, path, k: int) -> dict:
    """Stage 4 at step k: μ, dt·μ_max, dt*, Φ for both integrators, the dominant mode
    (eqs. 21–24) and its velocity direction for the alignment (eq. 27)."""
    row = read_columns(path, ["q", "v", "x_tilde", "s_min_G"], k, k + 1)
    T = robot.terms(row["q"][0], row["v"][0])
    gamma = conditioning_scale(T.s_min_G, spec.controller)
    K, D = block_gains(spec.controller, gamma)
    M_b = T.reduced_inertia
    J_x = theory.task_jacobian(row["x_tilde"][0], T.R_te)
    K_x = J_x.T @ K + theory.posture_stiffness(T.gamma_inv, spec.controller.gains.posture, J_x)
    mu = theory.damping_rates(M_b, D)
    dt, integ = spec.mission.dt, spec.controller.integrator
    maps = {i: theory.spectrum(theory.discrete_map(M_b, D, K_x, J_x, dt, i))
            for i in ("explicit", "imex")}
    own = maps[integ]
    e = own.dominant_vector[9:]
    e = np.real(e * np.exp(-1j * np.angle(e[np.argmax(np.abs(e))])))  # real direction
    direction = T.gamma_inv @ np.concatenate([np.zeros(3), e])
    dt_bis = theory.bisect_critical_step(M_b, D, K_x, J_x, "explicit")
    record = {
        "rule": "step of the window with the smallest logged s_min_G",
        "step": k, "t": k * dt, "s_min_G": T.s_min_G, "gamma": gamma,
        "mu": mu.tolist(), "mu_max": float(mu[-1]), "dt_mu_max": float(dt * mu[-1]),
        "dt_star": theory.critical_step(mu[-1]), "dt_star_bisection": dt_bis,
        "regime": theory.regime(dt * mu[-1]) if integ == "explicit" else "unconditionally stable",
        "rho_modes": theory.amplification(dt, mu, integ).tolist(),
        "eig_dominant": {"real": own.dominant.real, "imag": own.dominant.imag},
        "spectral_radius": own.spectral_radius,
        "maps": {i: {"eig_dominant": {"real": m.dominant.real, "imag": m.dominant.imag},
                     "spectral_radius": m.spectral_radius,
                     "eigenvalues": {"real": m.eigenvalues.real.tolist(),
                                     "imag": m.eigenvalues.imag.tolist()}}
                 for i, m in maps.items()},
        "integrator": integ, "dt": dt,
        "M_breve": M_b.tolist(), "D_breve": D.tolist(), "K_breve": K.tolist(),
        "J_x": J_x.tolist(), "K_x": K_x.tolist(),
    }
    return {"record": record, "direction": direction}


def bus_rate_statistics(w_b: np.ndarray) -> dict:
    """The bus angular rate ω_b alone: lag-1 of its dominant step-to-step component (eq. 25).

    The component is ω_b projected on its direction of most step-to-step energy; its
    alternating part, a = (x_k − 2x_{k+1} + x_{k+2})/4 (exact for a period-2 signal), is
    compared with its standard deviation to say how much of ω_b the ripple is.
    """
    x = w_b @ signals.dominant_step_direction(w_b)
    alt = (x[:-2] - 2 * x[1:-1] + x[2:]) / 4
    return {"lag1": float(signals.lag1_autocorrelation(x)), "std": float(x.std()),
            "step_rms": float(signals.step_rms(x)), "alternating_rms": float(signals.rms(alt))}


def mission_metrics(cols: dict[str, np.ndarray]) -> dict:
    """Window metrics: pointing and boresight errors, coverage, and how often each limit bound."""
    return {
        "pointing_err_deg_max": float(cols["pointing_err_deg"].max()),
        "boresight_err_deg_max": float(cols["boresight_err_deg"].max()),
        "coverage_final": float(cols["coverage"][-1]),
        "dt_mu_max_window_max": float(cols["dt_mu_max"].max()),
        "limit_share": {f: float(cols[f].mean()) for f in LIMIT_FLAGS},
    }


COMPARE_ROWS = (
    ("dominant lag-1", ("dominant", "lag1")),
    ("dominant direction σ", ("dominant", "sigma")),
    ("dt·μ_max", ("theory", "dt_mu_max")),
    ("dt* = 2/μ_max (s)", ("theory", "dt_star")),
    ("discrete-map dominant eigenvalue (real)", ("theory", "eig_dominant", "real")),
    ("discrete-map dominant eigenvalue (imag)", ("theory", "eig_dominant", "imag")),
    ("spectral radius", ("theory", "spectral_radius")),
    ("alignment |cos|", ("alignment", "abs_cos")),
    ("median ‖Δv‖", ("velocity_jump", "median")),
    ("bus rate ω_b: lag-1 of its dominant component", ("bus_rate", "lag1")),
    ("bus rate ω_b: alternating RMS (rad/s)", ("bus_rate", "alternating_rms")),
    ("provenance max |Δσ_min|", ("provenance", "max_abs_s_min_G")),
    ("max pointing error (deg)", ("metrics", "pointing_err_deg_max")),
    ("final coverage", ("metrics", "coverage_final")),
)


def dig(record: dict, path: tuple[str, ...]):
    for p in path:
        record = record[p]
    return record


def compare(a: dict, b: dict) -> dict:
    """Stage 7: the two runs side by side, the lag-1 flip and the amplitude ratio."""
    la, lb = a["dominant"]["lag1"], b["dominant"]["lag1"]
    return {
        "against": b["spec_name"], "against_log": b["log"],
        "lag1_flip": bool(np.sign(la) != np.sign(lb)),
        "amplitude_ratio": a["velocity_jump"]["median"] / b["velocity_jump"]["median"],
        "coverage_diff_pp": 100 * abs(a["metrics"]["coverage_final"]
                                      - b["metrics"]["coverage_final"]),
        "table": [{"quantity": label, a["spec_name"]: dig(a, p), b["spec_name"]: dig(b, p)}
                  for label, p in COMPARE_ROWS],
        "other": b,
    }
