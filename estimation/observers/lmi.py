"""Gain synthesis of the LPV adaptive observer by vertex LMIs (LPV (27)–(28), (35)).

The air-path model of LPV (3)–(5), ``ẋ = A(ρ)x + E``, ``y_m = C(ρ)x + Gψᵀθ``, is affine in
ρ, so the observer inequality holds on the whole ρ-box if it holds at its 2⁵ = 32 vertices
(docs/algorithms.md §3). Find ``P = Pᵀ ≻ 0``, ``Q = Qᵀ ≻ 0`` and ``Y`` such that, at every vertex,

    M(ρ) = [[AᵀP + PA − CᵀYᵀ − YC + Q,  YG,     C2ᵀ ],
            [GᵀYᵀ,                      −ε1 I,  0   ],
            [C2,                        0,      −ε2 I]]  ≺ 0,

then ``L = P⁻¹Y``. The raw units (Pa, rad/s, kg/s against ρ ~ 1e−7) make the SDP
ill-conditioned, so it is posed for the scaled model ``x = S_x x̃``, ``y = S_y ỹ``
(``Ã = S_x⁻¹AS_x``, ``C̃ = S_y⁻¹CS_x``, ``G̃ = S_y⁻¹G S_θ`` with ``S_θ = S_y[2]``), solved with
cvxpy + Clarabel, and mapped back: ``L = S_x L̃ S_y⁻¹``.

**Gain structure.** ``structure="decoupled"`` (default) restricts the search to
``P = blkdiag(P_12, p_3)`` and ``Y[2,0] = Y[2,2] = 0``, so ``L = P⁻¹Y`` has
``L[2,0] = L[2,2] = 0``: the turbo-speed estimate is corrected by the turbo-speed
measurement only (its row of ``A(ρ)`` has no pressure terms either). The adaptive law compares
``y_m2`` with ``C2(ρ)x̂ = ρ1 ω̂_t``, so whatever is injected into ``ω̂_t`` from the ``p_im``
residual (model and discretisation error of the fast manifold dynamics) or from the MAF
residual (which holds the not yet learnt map) goes straight into the map estimate. With the
paper's fast adaptation (Γ = 200 I) and noise-free signals the map's mean relative error
drops from 3.4 % to 1.9 % on ``maf-whtc`` and from 1.3 % to 1.1 % on ``maf-ftp75``; with
the observer's averaging (normalised) gain the two structures score the same. The
restricted ``P, Y`` are a special case of LPV (28), so Theorem 1 applies unchanged.
"""

from __future__ import annotations

import functools
import itertools
import threading
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from estimation.errors import ConfigError, ShapeError

N_RHO = 5
DEFAULT_STATE_SCALE = (1.0e5, 1.0e5, 1.0e4)  # Pa, Pa, rad/s
DEFAULT_OUTPUT_SCALE = (1.0e5, 1.0e4, 0.1)  # Pa, rad/s, kg/s
_STRICT = 1.0e-6  # the strict inequalities are imposed as ⪯ −δI / ⪰ δI


@dataclass(frozen=True, slots=True, eq=False)
class GainDesign:
    """A solved observer design.

    ``L`` (3, 3) is the gain in raw units (rates of Pa, Pa, rad/s per Pa, rad/s, kg/s of
    output residual); ``L_scaled`` the same gain for the scaled model; ``P``, ``Q`` the
    scaled Lyapunov and decay matrices; ``vertices`` (32, 5) the ρ corners; ``margins``
    (32,) ``−λ_max(M(ρ_w))`` per vertex (> 0: satisfied) and ``margin`` their minimum;
    ``closed_loop_eigs`` (32, 3) complex eigenvalues of ``A(ρ_w) − LC(ρ_w)`` [1/s].
    """

    L: np.ndarray
    L_scaled: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    state_scale: np.ndarray
    output_scale: np.ndarray
    vertices: np.ndarray
    margins: np.ndarray
    margin: float
    closed_loop_eigs: np.ndarray
    status: str
    a1: float
    a2: float
    eps1: float
    eps2: float
    structure: str = "decoupled"

    @property
    def hurwitz(self) -> bool:
        """True when ``A(ρ) − LC(ρ)`` is Hurwitz at every vertex."""
        return bool(np.all(self.closed_loop_eigs.real < 0.0))


def system_matrices(
    rho: np.ndarray, a1: float, a2: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``A(ρ)``, ``C(ρ)``, ``G``, ``C2(ρ)`` of LPV (3)–(5), (24)–(25) for one ρ (5,).

    ``A = [[−a1ρ3, a1ρ2, a1ρ1], [a2ρ3, −a2(ρ2+ρ4), 0], [0, 0, −ρ5]]``,
    ``C = [[1,0,0],[0,0,1],[0,0,ρ1]]``, ``G = [0,0,1]ᵀ``, ``C2 = [0, 0, ρ1]``.
    """
    r1, r2, r3, r4, r5 = (float(v) for v in rho)
    A = np.array(
        [
            [-a1 * r3, a1 * r2, a1 * r1],
            [a2 * r3, -a2 * (r2 + r4), 0.0],
            [0.0, 0.0, -r5],
        ]
    )
    C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, r1]])
    G = np.array([[0.0], [0.0], [1.0]])
    C2 = np.array([[0.0, 0.0, r1]])
    return A, C, G, C2


def box_vertices(rho_min: np.ndarray, rho_max: np.ndarray) -> np.ndarray:
    """The 2⁵ corners (32, 5) of the box ``[rho_min, rho_max]``."""
    lo = np.asarray(rho_min, dtype=np.float64)
    hi = np.asarray(rho_max, dtype=np.float64)
    return np.array([[hi[i] if b else lo[i] for i, b in enumerate(bits)]
                     for bits in itertools.product((0, 1), repeat=lo.size)])  # fmt: skip


def synthesize_gain(
    rho_min: np.ndarray | list[float],
    rho_max: np.ndarray | list[float],
    a1: float,
    a2: float,
    *,
    eps1: float = 0.25,
    eps2: float = 0.11,
    state_scale: tuple[float, float, float] = DEFAULT_STATE_SCALE,
    output_scale: tuple[float, float, float] = DEFAULT_OUTPUT_SCALE,
    max_P: float = 1.0e4,
    structure: Literal["decoupled", "full"] = "decoupled",
) -> GainDesign:
    """Solve the vertex LMIs of LPV (28)/(35) for the gain ``L = P⁻¹Y``.

    Parameters
    ----------
    rho_min, rho_max : (5,) bounds of ρ (LPV Table 1 style) in the units of
        :data:`estimation.plants.airpath.UNITS`.
    a1, a2 : LPV (5) constants ``R_a T_im / V_im``, ``R_e T_em / V_em`` [J/(kg m³)].
    eps1, eps2 : the fixed ε of LPV (28), both > 0 with ``ε1 + ε2 < 2`` (paper: 0.25, 0.11).
    state_scale, output_scale : scalings ``S_x``, ``S_y`` that make the SDP O(1).
    max_P : bound ``P ⪯ max_P·I`` keeping the scaled design bounded.
    structure : ``"decoupled"`` (``L[2,0] = L[2,2] = 0``, see the module docstring) or
        ``"full"`` (any ``P``, ``Y``).

    The objective maximises the common margin ``t`` (``M(ρ_w) ⪯ −tI`` at every vertex).
    Raises :class:`ConfigError` on bad inputs or when the SDP is infeasible.
    """
    import cvxpy as cp

    lo = np.asarray(rho_min, dtype=np.float64).ravel()
    hi = np.asarray(rho_max, dtype=np.float64).ravel()
    if lo.shape != (N_RHO,) or hi.shape != (N_RHO,):
        raise ShapeError(f"rho_min and rho_max must have 5 values, got {lo.size} and {hi.size}")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ConfigError(f"rho bounds must be finite, got {lo.tolist()} / {hi.tolist()}")
    if np.any(lo > hi):
        i = int(np.argmax(lo > hi))
        raise ConfigError(f"rho{i + 1}: lower bound {lo[i]:g} exceeds upper bound {hi[i]:g}")
    if not (eps1 > 0 and eps2 > 0):
        raise ConfigError(f"eps1 and eps2 must be > 0, got {eps1:g} and {eps2:g}")
    if eps1 + eps2 >= 2.0:
        raise ConfigError(f"eps1 + eps2 must be < 2 (LPV (28)), got {eps1:g} + {eps2:g}")
    if not (np.isfinite(max_P) and max_P > 0):
        raise ConfigError(f"max_P must be finite and > 0, got {max_P:g}")
    if structure not in ("decoupled", "full"):
        raise ConfigError(f"structure must be 'decoupled' or 'full', got {structure!r}")
    if not (np.isfinite(a1) and a1 > 0 and np.isfinite(a2) and a2 > 0):
        raise ConfigError(f"a1 and a2 must be finite and > 0, got {a1:g} and {a2:g}")
    sx = np.asarray(state_scale, dtype=np.float64)
    sy = np.asarray(output_scale, dtype=np.float64)
    if sx.shape != (3,) or sy.shape != (3,) or np.any(sx <= 0) or np.any(sy <= 0):
        raise ConfigError(f"scales must be 3 positive values, got {sx.tolist()}, {sy.tolist()}")

    vertices = box_vertices(lo, hi)
    Sx, Sy_inv = np.diag(sx), np.diag(1.0 / sy)
    scaled = []
    for rho in vertices:
        A, C, G, C2 = system_matrices(rho, a1, a2)
        scaled.append(
            (np.linalg.solve(Sx, A @ Sx), Sy_inv @ C @ Sx, Sy_inv @ G * sy[2], (C2 @ Sx) / sy[2])
        )
    lmi = _vertex_lmi(structure)
    with lmi.lock:
        for values, parameters in zip(scaled, lmi.vertices, strict=True):
            for value, parameter in zip(values, parameters, strict=True):
                parameter.value = value
        lmi.eps1.value, lmi.eps2.value, lmi.max_P.value = eps1, eps2, max_P
        try:
            lmi.problem.solve(solver=cp.CLARABEL)
        except cp.SolverError as exc:
            raise ConfigError(f"LPV gain LMI: solver failed ({exc})") from exc
        status = str(lmi.problem.status)
        t = lmi.t.value
        # copies, read under the lock: the next design overwrites the variables' values
        P, Q, Y = (np.array(v.value, dtype=np.float64) for v in (lmi.P, lmi.Q, lmi.Y))
    if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or t is None:
        raise ConfigError(
            f"LPV gain LMI is infeasible on the ρ-box (solver status {status!r}); "
            f"rho_min={lo.tolist()}, rho_max={hi.tolist()}"
        )
    Pv = 0.5 * (P + P.T)
    Qv = 0.5 * (Q + Q.T)
    Yv = Y
    if structure == "decoupled":  # exact zeros, not the solver's ~1e−12
        Pv[0, 2] = Pv[2, 0] = Pv[1, 2] = Pv[2, 1] = 0.0
        Yv[2, 0] = Yv[2, 2] = 0.0
    L_scaled = np.linalg.solve(Pv, Yv)
    margins = np.empty(vertices.shape[0])
    eigs = np.empty((vertices.shape[0], 3), dtype=np.complex128)
    L = Sx @ L_scaled @ Sy_inv
    for w, (As, Cs, Gs, C2s) in enumerate(scaled):
        top = As.T @ Pv + Pv @ As - Cs.T @ Yv.T - Yv @ Cs + Qv
        M = np.block(
            [
                [top, Yv @ Gs, C2s.T],
                [Gs.T @ Yv.T, -eps1 * np.eye(1), np.zeros((1, 1))],
                [C2s, np.zeros((1, 1)), -eps2 * np.eye(1)],
            ]
        )
        margins[w] = -np.linalg.eigvalsh(0.5 * (M + M.T)).max()
        A, C, _, _ = system_matrices(vertices[w], a1, a2)
        eigs[w] = np.linalg.eigvals(A - L @ C)
    margin = float(margins.min())
    if margin <= 0.0 or not np.all(eigs.real < 0.0):
        raise ConfigError(
            f"LPV gain LMI: no valid design on the ρ-box (status {status!r}, min margin "
            f"{margin:.3g}, max closed-loop Re λ {eigs.real.max():.3g}); "
            f"rho_min={lo.tolist()}, rho_max={hi.tolist()}"
        )
    return GainDesign(
        L=L,
        L_scaled=L_scaled,
        P=Pv,
        Q=Qv,
        state_scale=sx,
        output_scale=sy,
        vertices=vertices,
        margins=margins,
        margin=margin,
        closed_loop_eigs=eigs,
        status=status,
        a1=float(a1),
        a2=float(a2),
        eps1=float(eps1),
        eps2=float(eps2),
        structure=structure,
    )


@dataclass(frozen=True, slots=True, eq=False)
class _VertexLmi:
    """The vertex LMIs of one gain structure as a parametrised cvxpy problem: the scaled
    ``(Ã, C̃, G̃, C̃2)`` of each of the 32 vertices, ``ε1``, ``ε2`` and ``max_P`` are
    parameters, so cvxpy compiles the problem once per process and each later design only
    fills in the numbers (a design costs ~0.02 s instead of ~0.25 s of canonicalisation;
    ``mapwise bench --section observers``). ``lock`` serialises the designs of threads that
    share it."""

    problem: Any
    P: Any
    Q: Any
    Y: Any
    t: Any
    vertices: list[tuple[Any, Any, Any, Any]]
    eps1: Any
    eps2: Any
    max_P: Any
    lock: threading.Lock


def forget_compiled_lmis() -> None:
    """Drop the compiled vertex LMIs, so the next design compiles again (what a new process
    pays once per gain structure): for ``mapwise bench``'s first-design figure."""
    _vertex_lmi.cache_clear()


@functools.cache
def _vertex_lmi(structure: str) -> _VertexLmi:
    """LPV (28)/(35) at the 2⁵ vertices, ``M(ρ_w) ⪯ −tI``, maximising ``t`` (DPP form)."""
    import cvxpy as cp

    P = cp.Variable((3, 3), symmetric=True)
    Q = cp.Variable((3, 3), symmetric=True)
    Y = cp.Variable((3, 3))
    t = cp.Variable()
    eps1, eps2, max_P = cp.Parameter(pos=True), cp.Parameter(pos=True), cp.Parameter(pos=True)
    eye3 = np.eye(3)
    constraints = [P >> _STRICT * eye3, Q >> _STRICT * eye3, P << max_P * eye3, t <= 1.0]
    if structure == "decoupled":
        constraints += [P[0, 2] == 0, P[1, 2] == 0, Y[2, 0] == 0, Y[2, 2] == 0]
    vertices = []
    for _ in range(2**N_RHO):
        As, Cs = cp.Parameter((3, 3)), cp.Parameter((3, 3))
        Gs, C2s = cp.Parameter((3, 1)), cp.Parameter((1, 3))
        vertices.append((As, Cs, Gs, C2s))
        top = As.T @ P + P @ As - Cs.T @ Y.T - Y @ Cs + Q
        M = cp.bmat(
            [
                [top, Y @ Gs, C2s.T],
                [Gs.T @ Y.T, -eps1 * np.eye(1), np.zeros((1, 1))],
                [C2s, np.zeros((1, 1)), -eps2 * np.eye(1)],
            ]
        )
        constraints.append(0.5 * (M + M.T) << -t * np.eye(5))
    problem = cp.Problem(cp.Maximize(t), constraints)
    return _VertexLmi(problem, P, Q, Y, t, vertices, eps1, eps2, max_P, threading.Lock())
