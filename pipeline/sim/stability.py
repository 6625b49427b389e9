"""The 18×18 discrete map of the linearised loop, its spectrum and the critical steps (eqs. 22–24).

The map linearises the attitude-and-camera loop about a rest state (v̆ = v̆_des, x̃ = 0,
saturations inactive, γ constant). With z = [x̃; e], e = v̆ − v̆_des:

    explicit:  A_e = I − dt M̆⁻¹D̆,         B = −dt M̆⁻¹ K_x
    imex:      A_e = (M̆ + dt D̆)⁻¹ M̆,      B = −dt (M̆ + dt D̆)⁻¹ K_x
    K_x = J_xᵀ K̆ + K_posture

Two update orders of the configuration (eq. 22):

    simulator:  x̃⁺ = x̃ + dt J_x e⁺  (v̆ first, then q moves with the new velocity)
                Φ = [[I + dt J_x B, dt J_x A_e], [B, A_e]]
    note:       x̃⁺ = x̃ + dt J_x e   (fully explicit: q moves with the old velocity, the order
                the seed note's eigenvalue −2.81 matches)
                Φ = [[I, dt J_x], [B, A_e]]

The loop as flown (eq. 34, :func:`flown_map`): the plant that moves the robot between two
instants and the computation delay. Under the sampled-data plant the command is held over the
step (zero-order hold), so e ramps from e_k to e_{k+1} and x̃ advances by the trapezoid
dt J_x (e_k + e_{k+1})/2; with d steps of delay the step applies the velocity increment
computed d instants before, carried in the state. Every spectral radius the analysis prints
is this map's.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from pipeline.shapes import BREVE


def critical_step(mu_max: float) -> float:
    """dt*_damping = 2/μ_max: forward Euler on the damping alone is stable iff dt < it (eq. 24).
    With the stiffness the map's own bound (:func:`map_critical_step`) may be lower."""
    return 2.0 / mu_max


UPDATE_ORDERS = ("simulator", "note")


def command_map(M_breve: np.ndarray, D_breve: np.ndarray, K_x: np.ndarray, dt: float,
                integrator: str) -> tuple[np.ndarray, np.ndarray]:
    """(A_e, B) of the controller's command e_cmd = A_e e + B x̃ (eq. 22): the velocity error
    the step asks for at the next instant, explicit or imex."""
    n = M_breve.shape[0]
    if integrator == "explicit":
        return (np.eye(n) - dt * np.linalg.solve(M_breve, D_breve),
                -dt * np.linalg.solve(M_breve, K_x))
    if integrator == "imex":
        W = M_breve + dt * D_breve
        return np.linalg.solve(W, M_breve), -dt * np.linalg.solve(W, K_x)
    raise ValueError(f"unknown integrator {integrator!r}")


def discrete_map(M_breve: np.ndarray, D_breve: np.ndarray, K_x: np.ndarray, J_x: np.ndarray,
                 dt: float, integrator: str, order: str = "simulator") -> np.ndarray:
    """Φ, the 18×18 map z⁺ = Φ z of the linearised loop (eq. 22), for the simulator's update
    order (x̃ advances with e⁺) or the note's fully explicit one (x̃ advances with e)."""
    n = M_breve.shape[0]
    A_e, B = command_map(M_breve, D_breve, K_x, dt, integrator)
    if order == "simulator":
        return np.block([[np.eye(n) + dt * J_x @ B, dt * J_x @ A_e], [B, A_e]])
    if order == "note":
        return np.block([[np.eye(n), dt * J_x], [B, A_e]])
    raise ValueError(f"unknown update order {order!r} (one of {', '.join(UPDATE_ORDERS)})")


PLANTS = ("reduced", "sampled")


def flown_map(M_breve: np.ndarray, D_breve: np.ndarray, K_x: np.ndarray, J_x: np.ndarray,
              dt: float, integrator: str, plant: str = "reduced", delay: int = 0,
              fraction: float = 0.0) -> np.ndarray:
    """Φ of the loop as flown (eq. 34): the integrator's command, the plant that moves the
    robot between two instants, and ``delay`` steps of computation delay.

    ``reduced``: the simulator's update of eq. 22 (the commanded velocity is the next one; no
    delay: the simulator has none). ``sampled``: the command held over the step (zero-order
    hold), its velocity increment p_k = e_cmd,k − e_k = B x̃_k + (A_e − I) e_k applied
    ``delay`` instants late, e_{k+1} = e_k + p_{k−d}, x̃_{k+1} = x̃_k + dt J_x (e_k + e_{k+1})/2.
    The state is z = [x̃; e] (18), and with a delay the increments computed and not yet
    applied, oldest first: w = [x̃; e; p_{k−d}; …; p_{k−1}] (18 + 9d). With ``fraction`` δ > 0
    the command arrives δ·dt into the step (eq. 41): :func:`split_map_terms` at that δ."""
    n = M_breve.shape[0]
    if plant == "reduced":
        if delay or fraction:
            raise ValueError("the reduced plant (the simulator's update) has no delay")
        return discrete_map(M_breve, D_breve, K_x, J_x, dt, integrator)
    if plant != "sampled":
        raise ValueError(f"unknown plant {plant!r} (one of {', '.join(PLANTS)})")
    if fraction:
        A0, A1, A2 = split_map_terms(M_breve, D_breve, K_x, J_x, dt, integrator, delay)
        return A0 + fraction * A1 + fraction**2 * A2
    A_e, B = command_map(M_breve, D_breve, K_x, dt, integrator)
    eye = np.eye(n)
    increment = np.hstack([B, A_e - eye])  # p_k from z_k
    if delay == 0:
        x_row = np.hstack([eye, dt * J_x]) + 0.5 * dt * J_x @ increment
        return np.vstack([x_row, np.hstack([np.zeros((n, n)), eye]) + increment])
    size = 2 * n + delay * n
    Phi = np.zeros((size, size))
    oldest = slice(2 * n, 3 * n)
    Phi[:n, :n], Phi[:n, n:2 * n], Phi[:n, oldest] = eye, dt * J_x, 0.5 * dt * J_x
    Phi[n:2 * n, n:2 * n], Phi[n:2 * n, oldest] = eye, eye
    for j in range(delay - 1):  # the queue moves up by one slot
        Phi[2 * n + j * n:3 * n + j * n, 3 * n + j * n:4 * n + j * n] = eye
    Phi[size - n:, :2 * n] = increment  # the newest slot: this step's increment
    return Phi


def split_map_terms(M_breve: np.ndarray, D_breve: np.ndarray, K_x: np.ndarray,
                    J_x: np.ndarray, dt: float, integrator: str, delay: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A₀, A₁, A₂) with Φ(δ) = A₀ + δ A₁ + δ² A₂, the sampled loop's map when step k's
    command arrives (d + δ)·dt after its instant (eq. 41). The step holds p_{k−d−1} for δ·dt,
    then p_{k−d}:

        e_{k+1} = e_k + δ p_{k−d−1} + (1 − δ) p_{k−d}
        x̃_{k+1} = x̃_k + dt J_x (e_k + (δ − δ²/2) p_{k−d−1} + (1 − δ)²/2 p_{k−d})

    (the integral of the piecewise-linear e over the step), on the state
    w = [x̃; e; p_{k−d−1}; …; p_{k−1}] (18 + 9(d + 1)); p_{k−d} is this step's increment
    when d = 0."""
    n = M_breve.shape[0]
    A_e, B = command_map(M_breve, D_breve, K_x, dt, integrator)
    eye, hJ = np.eye(n), dt * J_x
    size = 2 * n + (delay + 1) * n
    increment = np.zeros((n, size))
    increment[:, :2 * n] = np.hstack([B, A_e - eye])  # p_k from w_k
    slot = [slice(2 * n + j * n, 3 * n + j * n) for j in range(delay + 1)]
    if delay == 0:
        after = increment
    else:
        after = np.zeros((n, size))
        after[:, slot[1]] = eye
    before = np.zeros((n, size))
    before[:, slot[0]] = eye
    x, e = slice(0, n), slice(n, 2 * n)
    A0, A1, A2 = np.zeros((size, size)), np.zeros((size, size)), np.zeros((size, size))
    A0[x, x], A0[x, e] = eye, hJ
    A0[x] += 0.5 * hJ @ after
    A0[e, e] = eye
    A0[e] += after
    for j in range(delay):  # the queue moves up by one slot
        A0[slot[j], slot[j + 1]] = eye
    A0[slot[delay]] = increment  # the newest slot: this step's increment
    A1[x] = hJ @ (before - after)
    A1[e] = before - after
    A2[x] = 0.5 * hJ @ (after - before)
    return A0, A1, A2


def uniform_moments(low: float, high: float, order: int) -> np.ndarray:
    """E[δ^m], m = 0 … ``order``, of δ uniform on [low, high] (a point when they are equal)."""
    m = np.arange(order + 1)
    if high == low:
        return float(low) ** m
    return (high ** (m + 1) - low ** (m + 1)) / ((m + 1) * (high - low))


def mean_square_radius(terms: tuple[np.ndarray, ...], low: float, high: float) -> float:
    """ρ_ms = √ρ(E[Φ(δ) ⊗ Φ(δ)]) for δ drawn afresh each step, uniform on [low, high]
    (eq. 41c): the loop with a jittered arrival is stable in mean square (E‖w_k‖² → 0) iff
    ρ_ms < 1; without jitter it is the map's own spectral radius. The second-moment map
    P ↦ Σ_ij E[δ^{i+j}] A_i P A_jᵀ is completely positive, so its spectral radius is an
    eigenvalue with a positive semi-definite eigenvector: it is taken on the symmetric
    matrices (their upper triangles, n(n + 1)/2 of them), by LAPACK's dense eigensolver (the
    slow modes' products cluster at the top, where a Krylov method stalls)."""
    size = terms[0].shape[0]
    moments = uniform_moments(low, high, 2 * (len(terms) - 1))
    S = sum(moments[i + j] * np.kron(Ai, Aj) for i, Ai in enumerate(terms)
            for j, Aj in enumerate(terms))
    iu, ju = np.triu_indices(size)
    rows = S[iu * size + ju]  # the image's upper triangle …
    # … of a symmetric P from its upper triangle: P_ab and P_ba both for a ≠ b.
    sym = rows[:, iu * size + ju] + np.where(iu != ju, 1.0, 0.0) * rows[:, ju * size + iu]
    return float(np.sqrt(np.max(np.abs(np.linalg.eigvals(sym)))))


@dataclass(frozen=True)
class MapSpectrum:
    eigenvalues: np.ndarray
    dominant: complex
    spectral_radius: float
    dominant_vector: np.ndarray  # eigenvector of the dominant eigenvalue (18)


def spectrum(Phi: np.ndarray) -> MapSpectrum:
    """Eigenvalues of Φ, its dominant one (largest modulus) and its eigenvector."""
    w, V = np.linalg.eig(Phi)
    i = int(np.argmax(np.abs(w)))
    return MapSpectrum(w, complex(w[i]), float(abs(w[i])), V[:, i])


def spectral_radius(Phi: np.ndarray) -> float:
    """max |λ| of Φ: its eigenvalues alone (no vectors, about a third cheaper than
    :func:`spectrum`)."""
    return float(np.max(np.abs(np.linalg.eigvals(Phi))))


def map_critical_step(M_breve, D_breve, K_x, J_x, integrator: str = "explicit",
                      lo: float = 1e-6, hi: float = 1.0, tol: float = 1e-10,
                      plant: str = "reduced", delay: int = 0, fraction: float = 0.0
                      ) -> float | None:
    """dt*_map: the dt in [lo, hi] where the spectral radius of the flown map Φ(dt) (eq. 34;
    a command arriving ``fraction`` of a step later, eq. 41) reaches 1, to ``tol`` relative.

    Assumes ρ(Φ(lo)) < 1 (a stable small step); returns None if ρ(Φ(hi)) < 1 (no bound in
    range, as for imex). The radius crosses 1 once on this bracket for a damped loop. Near
    dt = 0 it creeps up to 1 from below (Φ → I) and at dt = 1 it is in the hundreds, so the
    crossing is first bracketed within a factor of 2, searching from the damping-only bound
    2/μ_max (eq. 24, which it is near), then found by Brent's method (SciPy's ``brentq``) on
    ρ − 1: about fifteen maps where a bisection of [lo, hi] to the same tolerance needs about
    forty. The guard pays it once per run, the analysis once per record.
    """
    from scipy.optimize import brentq

    from pipeline.sim.breve_controller import damping_rates  # compiled: imported on use

    @functools.cache  # the bracket's ends are asked for again by the search and by brentq
    def excess(dt: float) -> float:
        return spectral_radius(flown_map(M_breve, D_breve, K_x, J_x, dt, integrator, plant,
                                         delay, fraction)) - 1.0

    if excess(hi) < 0.0:
        return None
    if excess(lo) >= 0.0:
        return lo
    mu_max = float(damping_rates(np.ascontiguousarray(M_breve),
                                 np.ascontiguousarray(D_breve))[-1])
    a = min(max(critical_step(mu_max) if mu_max > 0.0 else hi, lo), hi)
    b = a
    while a > lo and excess(a) >= 0.0:  # down to a stable step
        b, a = a, max(0.5 * a, lo)
    while b < hi and (b == a or excess(b) < 0.0):  # up to an unstable one
        a, b = b, min(2.0 * b, hi)
    return float(brentq(excess, a, b, xtol=tol * lo, rtol=tol))


def posture_stiffness(gamma_inv: np.ndarray, k_posture: float, J_x: np.ndarray) -> np.ndarray:
    """Posture spring in x̃ coordinates: (Γ⁻¹[6:, 3:])ᵀ k Γ⁻¹[6:, 3:] J_x⁻¹ (eq. 13e, 22)."""
    P = gamma_inv[6:, 3:]
    return k_posture * P.T @ P @ np.linalg.inv(J_x)


def position_jacobian(J_x: np.ndarray, n_breve: int) -> np.ndarray:
    """The map's position rate per v̆ (eqs. 22, 37f): J_x of the task error x̃ (9×9), and for a
    redundant arm the null-space coordinates η with η̇ = ν_n below it, blockdiag(J_x, I_k)."""
    if n_breve == J_x.shape[0]:
        return J_x
    out = np.eye(n_breve)
    out[:J_x.shape[0], :J_x.shape[1]] = J_x
    return out


def mode_stiffness(K_breve: np.ndarray, ctrl, shape) -> np.ndarray:
    """The block stiffness on v̆'s coordinates for the modes' undamped frequencies (eqs. 13,
    37f): K̆ on the task blocks and a redundant arm's null-space stiffness K_n on ν_n's."""
    k = shape.null_space_dim
    if not k:
        return K_breve
    out = np.zeros((shape.n_breve, shape.n_breve))
    out[:K_breve.shape[0], :K_breve.shape[1]] = K_breve
    out[K_breve.shape[0]:, K_breve.shape[1]:] = ctrl.null_space.K * np.eye(k)
    return out


def loop_stiffness(J_x: np.ndarray, K_breve: np.ndarray, gamma_inv: np.ndarray,
                   ctrl) -> np.ndarray:
    """K_x, the stiffness in the map's position coordinates (eqs. 13, 22, 37f): J_xᵀK̆ on the
    task error, the posture spring (``ctrl.gains.posture``), and a redundant arm's null-space
    spring K_n Z̃ᵀ(q − q̄) in ν_n's rows (``ctrl.null_space.K``); ``ctrl`` the spec's
    ``controller`` block, ``J_x`` from :func:`position_jacobian` (q − q̄ moves by Γ⁻¹[6:, 3:]
    per unit of the coordinates v̆ integrates)."""
    k_posture = ctrl.gains.posture
    k_null = 0.0 if ctrl.null_space is None else ctrl.null_space.K
    n, task = J_x.shape[0], K_breve.shape[0]
    if n == task:
        return J_x.T @ K_breve + posture_stiffness(gamma_inv, k_posture, J_x)
    P = gamma_inv[6:, 3:]
    S = k_posture * P.T @ P
    S[task:] += k_null * gamma_inv[6:, 12:].T @ P
    K_x = S @ np.linalg.inv(J_x)
    K_x[:task, :task] += J_x[:task, :task].T @ K_breve
    return K_x


# -- The damping modes and their fixes (eqs. 21, 24) -----------------------------------------

# The nine reduced coordinates v̆ = [ω_b ; ν_e,lin ; ν_e,ang] (eq. 2): ω_b in the bus frame (z
# along the shoulder-pan axis on both shipped robots), ν_e in the camera frame (z the boresight).
REDUCED_AXES = ("bus ω_b,x", "bus ω_b,y", "bus yaw ω_b,z",
                "camera ν_e,x", "camera ν_e,y", "camera ν_e,z (along the boresight)",
                "camera ω_e,x", "camera ω_e,y", "camera roll ω_e,z (about the boresight)")
# Their symbols alone, for axis labels.
REDUCED_SYMBOLS = ("ω_b,x", "ω_b,y", "ω_b,z", "ν_e,x", "ν_e,y", "ν_e,z", "ω_e,x", "ω_e,y", "ω_e,z")
BUS_YAW_AXIS = 2  # ω_b,z: the mode μ_bus = D_b/I_zz,bus of the robot card predicts (eq. 21)
# The blocks of D̆ and the spec's gains that set them (eqs. 13, 37f): the three task blocks of
# three, then a redundant arm's null-space block (controller.null_space.D), the rest of v̆.
GAIN_BLOCKS = ("bus", "cam_pos", "cam_ori", "null_space")
GAIN_FIELDS = {"bus": "controller.gains.bus.D", "cam_pos": "controller.gains.cam_pos.D",
               "cam_ori": "controller.gains.cam_ori.D", "null_space": "controller.null_space.D"}


def block_slices(n_breve: int) -> tuple[slice, ...]:
    """v̆'s gain blocks for a v̆ of ``n_breve`` components (eqs. 13, 37f): the task blocks of
    :data:`pipeline.shapes.BREVE`, then the null space's to the end."""
    task = (BREVE.omega_b, BREVE.nu_e_lin, BREVE.nu_e_ang)
    null = BREVE.null_space.start
    return task + ((slice(null, n_breve),) if n_breve > null else ())


def axis_name(i: int) -> str:
    """Reduced coordinate i by name: :data:`REDUCED_AXES`, then a redundant arm's null-space
    velocities (eq. 37)."""
    return REDUCED_AXES[i] if i < len(REDUCED_AXES) else f"null-space ν_n,{i - 8}"


def axis_symbol(i: int) -> str:
    """Reduced coordinate i's symbol alone, for axis labels."""
    return REDUCED_SYMBOLS[i] if i < len(REDUCED_SYMBOLS) else f"ν_n,{i - 8}"
# Forward Euler on ė = −μ e is stable iff dt·μ < 2 (eq. 24). With one step of computation delay
# (the command of step k from the state of step k − 1) it reads e⁺ = e − dt·μ·e⁻, whose
# characteristic equation z² − z + dt·μ = 0 has its roots on the unit circle at dt·μ = 1: the
# bound halves. dt·μ ≤ 1 is therefore both a margin of two on the undelayed loop and the
# stability bound of the delayed one.
DT_MU_STABLE = 2.0
DT_MU_MARGIN = 1.0


@dataclass(frozen=True)
class DampingMode:
    """One eigenpair of M̆⁻¹D̆ (eq. 21): M̆⁻¹D̆ e = μ e, eᵀ M̆ e = 1.

    With D̆ = Σ_j d_j P_j (P_j the projector on block j), μ = eᵀ D̆ e = Σ_j d_j ‖P_j e‖²: the
    share of block j in μ is d_j ‖P_j e‖² / μ, which is also ∂ln μ/∂ln d_j, how strongly its
    gain sets the rate."""

    mu: float  # 1/s
    vector: np.ndarray  # e (9, or 9 + k for a redundant arm), M̆-normalised
    shares: np.ndarray  # the share of each gain block in μ (block_slices), summing to 1
    axis: int  # the reduced coordinate of largest |e_i| within the dominant block

    @property
    def block(self) -> int:
        return int(np.argmax(self.shares))

    @property
    def name(self) -> str:
        return axis_name(self.axis)

    @property
    def null_space(self) -> bool:
        """Whether a redundant arm's null-space damping sets it (eq. 37f)."""
        return self.block == GAIN_BLOCKS.index("null_space")


def _modes(M_breve: np.ndarray, D_breve: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[slice]]:
    """(μ, E, shares, blocks): every eigenpair of D̆ e = μ M̆ e (SciPy's symmetric-definite
    generalized eigensolver), unsorted, and each mode's share of each gain block (a row per
    mode), vectorised: the fix searches call this hundreds of times."""
    import scipy.linalg

    mu, E = scipy.linalg.eigh(D_breve, M_breve, check_finite=False)
    d = np.diag(D_breve)
    blocks = block_slices(len(d))
    # Each mode's damping energy per axis, one contiguous row per mode (a row's sums are those
    # of the mode's own vector). An undamped mode (μ = 0, a block's gain at 0) has no share:
    # it goes by ‖P_j e‖².
    squares = np.ascontiguousarray(E.T) ** 2
    per_axis = np.where((mu > 0)[:, None], d * squares, squares)
    shares = (np.stack([per_axis[:, sl].sum(axis=1) for sl in blocks], axis=1)
              / per_axis.sum(axis=1)[:, None])
    return mu, E, shares, blocks


def damping_modes(M_breve: np.ndarray, D_breve: np.ndarray) -> list[DampingMode]:
    """Every damping mode of M̆⁻¹D̆, fastest first (eq. 21), from SciPy's symmetric-definite
    generalized eigensolver (D̆ e = μ M̆ e; not a per-step computation)."""
    mu, E, shares, blocks = _modes(M_breve, D_breve)
    modes = []
    for i in np.argsort(mu)[::-1]:
        e = E[:, i]
        b = int(np.argmax(shares[i]))
        axis = blocks[b].start + int(np.argmax(np.abs(e[blocks[b]])))
        modes.append(DampingMode(float(mu[i]), e, shares[i].copy(), axis))
    return modes


def fastest_in_block(M_breve: np.ndarray, D_breve: np.ndarray, block: int) -> float | None:
    """μ of the fastest damping mode whose largest share is block ``block``'s (the
    ``DampingMode.block`` of :func:`damping_modes`), None when no mode is that block's."""
    mu, _, shares, _ = _modes(M_breve, D_breve)
    mine = mu[np.argmax(shares, axis=1) == block]
    return float(mine.max()) if mine.size else None


def with_gain(D_breve: np.ndarray, block: int, d: float) -> np.ndarray:
    """D̆ with the damping gain of block ``block`` set to d (eqs. 13, 37f)."""
    D = D_breve.copy()
    sl = block_slices(len(D))[block]
    D[sl, sl] = d * np.eye(sl.stop - sl.start)
    return D


def mu_max_with_gain(M_breve: np.ndarray, D_breve: np.ndarray, block: int, d: float) -> float:
    """μ_max of M̆⁻¹D̆ with the damping gain of block ``block`` set to d (eq. 21)."""
    return damping_modes(M_breve, with_gain(D_breve, block, d))[0].mu


def largest_stable_gain(M_breve: np.ndarray, D_breve: np.ndarray, block: int,
                        mu_bound: float, rtol: float = 1e-9) -> float | None:
    """The largest damping gain d of block ``block`` (the other blocks as they are) with every
    μ of M̆⁻¹D̆ at most ``mu_bound``; None when even d = 0 leaves a faster mode.

    μ_max grows monotonically with d (D̆ grows by a positive semi-definite term), so it is
    bisected; the bracket's upper end is the d at which the block alone would reach the bound
    in its slowest direction."""
    def mu_max(d: float) -> float:
        return mu_max_with_gain(M_breve, D_breve, block, d)

    if mu_max(0.0) > mu_bound:
        return None
    lo, hi = 0.0, 1.0
    while mu_max(hi) <= mu_bound:
        lo, hi = hi, 2.0 * hi
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mu_max(mid) <= mu_bound else (lo, mid)
    return lo


@dataclass(frozen=True)
class ModeFixes:
    """The fixes of the fastest mode at step dt (eq. 24): the largest step, and the largest
    gain of its dominant block, for stability (dt·μ < 2) and with the margin dt·μ ≤ 1 (the
    bound under one step of delay)."""

    mode: DampingMode
    dt: float
    gain_block: str  # one of GAIN_BLOCKS
    gain: float  # its damping gain now (the diagonal of D̆, after any derate)
    dt_stable: float  # 2/μ
    dt_margin: float  # 1/μ
    gain_stable: float | None  # the largest gain with every dt·μ < 2
    gain_margin: float | None  # ... with every dt·μ ≤ 1
    mu_without: float  # μ_max with that gain at 0: the floor it cannot fix, 1/s

    @property
    def dt_mu(self) -> float:
        return self.dt * self.mode.mu


def mode_fixes(M_breve: np.ndarray, D_breve: np.ndarray, dt: float) -> ModeFixes:
    """The fastest damping mode of M̆⁻¹D̆ and its fixes at step dt (eqs. 21, 24)."""
    fastest = damping_modes(M_breve, D_breve)[0]
    b = fastest.block
    first = block_slices(len(D_breve))[b].start
    return ModeFixes(
        fastest, dt, GAIN_BLOCKS[b], float(D_breve[first, first]),
        DT_MU_STABLE / fastest.mu, DT_MU_MARGIN / fastest.mu,
        largest_stable_gain(M_breve, D_breve, b, DT_MU_STABLE / dt),
        largest_stable_gain(M_breve, D_breve, b, DT_MU_MARGIN / dt),
        mu_max_with_gain(M_breve, D_breve, b, 0.0))
