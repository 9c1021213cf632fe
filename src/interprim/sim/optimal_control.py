"""Optimal-control synthesis of reaching movements (the training data of paper Sec. IV).

For one arm, a goal point ``g`` for the hand and attractor points ``a_m``, we
look for the joint trajectory ``q(s)`` over normalised time ``s in [0, 1]`` that
solves::

    min_q   w_e  * int_0^1 sum_j W_j q_j''(s)^2 ds                     (effort)
          + w_a  * int_0^1 sum_m k_m(s) ||hand(q(s)) - a_m||^2 ds       (attractors)
    s.t.    q(0) = q_rest,  q'(0) = q''(0) = 0                          (start at rest)
            hand(q(1)) = g,  q'(1) = q''(1) = 0                         (hard goal constraint)
            q_lo <= q(s_k) <= q_hi  on the quadrature grid s_k          (joint limits)

with ``k_m(s) = exp(-(s - s_m)^2 / (2 w^2))`` a bump around the attractor's time
``s_m`` (mid-movement by default).  Because the optimum is computed in
normalised time, its shape does not depend on the duration of the movement:
effort in real time scales every term by the same power of the duration.

Direct method with a smooth basis (rather than one variable per knot): the
trajectory is::

    q(s) = q_rest + h(s) (q_T - q_rest) + sum_b psi_b(s) c_b

with ``h`` the minimum-jerk polynomial ``10 s^3 - 15 s^4 + 6 s^5`` and
``psi_b(s) = 64 (s (1 - s))^3 P_b(2 s - 1)`` (``P_b`` Legendre polynomials),
which satisfy all boundary conditions by construction.  The free variables are
the final posture ``q_T`` and ``n_basis`` coefficients per joint, so the problem
has ``n (1 + n_basis)`` variables: the effort is an exact quadratic form, the
attractor cost is evaluated on a grid of ``n_knots`` points, gradients are
analytic, and SLSQP (:func:`scipy.optimize.minimize`) handles the two goal
equalities and the linear joint-limit inequalities.  One solve takes a few
milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TrajectoryBasis", "ReachSolution", "solve_reach"]


class TrajectoryBasis:
    """Rest-to-rest trajectory basis on normalised time ``s in [0, 1]``.

    Column 0 is the minimum-jerk ramp ``h(s)`` (0 -> 1); columns ``1..n_basis``
    are bumps ``psi_b`` that vanish with their first two derivatives at both ends.

    Parameters
    ----------
    n_basis : int
        Number of bump functions ``psi_b`` per joint.
    """

    def __init__(self, n_basis: int = 5):
        if int(n_basis) < 0:
            raise ValueError(f"n_basis must be >= 0, got {n_basis}")
        self.n_basis = int(n_basis)

    @property
    def size(self) -> int:
        """Number of columns, ``1 + n_basis``."""
        return 1 + self.n_basis

    def matrices(self, s):
        """Values and first and second derivatives of all basis functions.

        Parameters
        ----------
        s : array_like, shape (K,)
            Normalised times in [0, 1].

        Returns
        -------
        M0, M1, M2 : ndarray, shape (K, 1 + n_basis) each
            ``M0[k, b] = basis_b(s_k)``, ``M1`` and ``M2`` its derivatives with
            respect to ``s``.
        """
        from numpy.polynomial import Polynomial as P
        from numpy.polynomial import legendre

        s = np.asarray(s, dtype=float).reshape(-1)
        polys = [P([0, 0, 0, 10, -15, 6])]
        env = 64.0 * P([0, 1, -1]) ** 3  # 64 (s - s^2)^3, max 1 at s = 1/2
        for b in range(self.n_basis):
            leg = legendre.Legendre.basis(b, domain=[0, 1]).convert(kind=P)  # P_b(2 s - 1)
            polys.append(env * leg)
        M0 = np.stack([p(s) for p in polys], axis=1)
        M1 = np.stack([p.deriv(1)(s) for p in polys], axis=1)
        M2 = np.stack([p.deriv(2)(s) for p in polys], axis=1)
        return M0, M1, M2


@dataclass
class ReachSolution:
    """The result of :func:`solve_reach`.

    Attributes
    ----------
    coef : ndarray, shape (1 + n_basis, n)
        Row 0: ``q_T - q_rest``; rows 1..: bump coefficients ``c_b``.
    q_rest : ndarray, shape (n,)
    basis : TrajectoryBasis
    cost : float
        Optimal value of the objective.
    effort : float
        The effort term of the optimum.
    hand_error : float
        ``||hand(q_T) - goal||`` in metres.
    success : bool
        Whether SLSQP reported convergence.
    n_iter : int
        SLSQP iterations (of the last solve).
    limits_constrained : bool
        Whether the joint-limit inequalities had to be added (the first solve
        without them left the limits somewhere on the grid).
    """

    coef: np.ndarray
    q_rest: np.ndarray
    basis: TrajectoryBasis
    cost: float
    effort: float
    hand_error: float
    success: bool
    n_iter: int
    limits_constrained: bool = False

    @property
    def q_final(self) -> np.ndarray:
        """Final posture ``q_T`` (radians)."""
        return self.q_rest + self.coef[0]

    def __call__(self, s) -> np.ndarray:
        """Joint angles at normalised times ``s``: ``(K,)`` -> ``(K, n)``."""
        M0, _, _ = self.basis.matrices(s)
        return self.q_rest + M0 @ self.coef

    def sample(self, n_frames: int) -> np.ndarray:
        """The trajectory on ``n_frames`` equally spaced normalised times (first = rest, last = goal)."""
        return self(np.linspace(0.0, 1.0, int(n_frames)))


def _bump(s, times, width):
    return np.exp(-0.5 * ((s[:, None] - times[None, :]) / width) ** 2)  # (K, m)


def solve_reach(
    arm,
    goal,
    attractors=None,
    attractor_times=0.5,
    attractor_width: float = 0.15,
    w_effort: float = 1.0,
    w_attractor: float = 2000.0,
    joint_weights=None,
    n_basis: int = 5,
    n_knots: int = 50,
    q_final_guess=None,
    limit_margin: float = 1e-3,
    maxiter: int = 200,
    ftol: float = 1e-7,
    _basis_cache: dict | None = None,
) -> ReachSolution:
    """Minimum-effort reaching movement of ``arm`` from rest to ``goal``, passing near attractors.

    Parameters
    ----------
    arm : PlanarArm
        The arm (its ``rest`` posture is the start, its ``joint_limits`` are enforced).
    goal : (2,) array_like
        Hand position to reach at ``s = 1`` (hard equality constraint), metres.
    attractors : array_like, shape (m, 2), optional
        Attractor points for the hand, metres.
    attractor_times : float or array_like, shape (m,)
        Normalised time at which each attractor pulls hardest (default 0.5).
    attractor_width : float
        Width (normalised time) of the Gaussian weighting around each attractor time.
    w_effort, w_attractor : float
        Weights of the effort (squared joint accelerations, rad^2) and attractor
        (squared distance, m^2) terms.
    joint_weights : array_like, shape (n,), optional
        Per-joint effort weights ``W_j`` (default: 2, 1, 0.5, ... from shoulder
        outwards: proximal joints move more mass).
    n_basis : int
        Bump functions per joint (see :class:`TrajectoryBasis`).
    n_knots : int
        Quadrature grid for the attractor cost and the joint-limit constraints.
    q_final_guess : array_like, shape (n,), optional
        Initial guess of the final posture (default: inverse kinematics of ``goal``).
    limit_margin : float
        The joint limits are imposed on the ``n_knots`` grid shrunk by this
        margin (radians), so that the smooth trajectory stays inside the true
        limits between grid points as well.
    maxiter, ftol : SLSQP options.

    Returns
    -------
    ReachSolution
    """
    from scipy.optimize import minimize

    goal = np.asarray(goal, dtype=float).reshape(2)
    n = arm.n_joints
    q_rest = arm.rest.copy()
    lo, hi = arm.joint_limits[:, 0], arm.joint_limits[:, 1]
    if attractors is None:
        attractors = np.zeros((0, 2))
    A = np.asarray(attractors, dtype=float).reshape(-1, 2)
    m = A.shape[0]
    t_att = np.broadcast_to(np.asarray(attractor_times, dtype=float), (m,))
    W = np.asarray(joint_weights, dtype=float) if joint_weights is not None else 2.0 ** -np.arange(n) * 2.0

    key = (n_basis, n_knots)
    cache = _basis_cache if _basis_cache is not None else {}
    if key not in cache:
        basis = TrajectoryBasis(n_basis)
        s = np.linspace(0.0, 1.0, n_knots)
        M0, _, M2 = basis.matrices(s)
        ds = 1.0 / (n_knots - 1)
        wq = np.full(n_knots, ds)
        wq[[0, -1]] *= 0.5  # trapezoid
        # effort: exact Gram matrix of second derivatives (Gauss-Legendre, polynomial integrand)
        xg, wg = np.polynomial.legendre.leggauss(12)
        _, _, G2 = basis.matrices(0.5 * (xg + 1.0))
        H = (G2 * (0.5 * wg)[:, None]).T @ G2  # (B1, B1)
        cache[key] = (basis, s, M0, wq, H)
    basis, s, M0, wq, H = cache[key]
    B1 = basis.size
    kern = _bump(s, t_att, attractor_width) * wq[:, None] if m else np.zeros((n_knots, 0))  # (K, m)

    def fun_grad(z):
        Z = z.reshape(B1, n)
        HZ = H @ Z
        f = w_effort * float(np.sum(Z * HZ * W))
        g = 2.0 * w_effort * HZ * W
        if m:
            P, J = arm.hand_and_jacobian(q_rest + M0 @ Z)  # (K, 2), (K, 2, n)
            diff = P[:, None, :] - A[None, :, :]  # (K, m, 2)
            f += w_attractor * float(np.sum(kern[:, :, None] * diff * diff))
            r = (2.0 * w_attractor) * (kern[:, :, None] * diff).sum(axis=1)  # (K, 2)
            g = g + M0.T @ (J[:, 0, :] * r[:, :1] + J[:, 1, :] * r[:, 1:])
        return f, g.ravel()

    def eq_fun(z):
        return arm.hand(q_rest + z[:n]) - goal

    def eq_jac(z):
        Jg = np.zeros((2, B1 * n))
        Jg[:, :n] = arm.jacobian(q_rest + z[:n])
        return Jg

    if q_final_guess is None:
        q_final_guess = arm.inverse_kinematics(
            goal, q_pref=0.5 * (q_rest + 0.5 * (lo + hi)), tol=1e-6, polish=False
        )
    z0 = np.zeros((B1, n))
    z0[0] = np.clip(q_final_guess, lo, hi) - q_rest
    bounds = [(None, None)] * (B1 * n)
    for j in range(n):
        bounds[j] = (lo[j] - q_rest[j], hi[j] - q_rest[j])
    constraints = [{"type": "eq", "fun": eq_fun, "jac": eq_jac}]

    def run(z_init, cons):
        return minimize(
            fun_grad,
            z_init,
            jac=True,
            method="SLSQP",
            bounds=bounds,
            constraints=cons,
            options={"maxiter": maxiter, "ftol": ftol},
        )

    # Active-set shortcut: the joint limits on the grid are linear inequalities,
    # but they rarely bind; solve without them first and add them only if the
    # solution leaves the limits anywhere on the grid.
    res = run(z0.ravel(), constraints)
    limits_constrained = False
    Q = q_rest + M0 @ res.x.reshape(B1, n)
    if not res.success or np.any(Q < lo - 1e-9) or np.any(Q > hi + 1e-9):
        Lin = np.kron(M0, np.eye(n))  # vec(M0 Z), row-major
        lo_v = np.tile(lo + limit_margin - q_rest, n_knots)
        hi_v = np.tile(hi - limit_margin - q_rest, n_knots)
        Lin2 = np.vstack([Lin, -Lin])
        ineq = {
            "type": "ineq",
            "fun": lambda z: np.concatenate([Lin @ z - lo_v, hi_v - Lin @ z]),
            "jac": lambda z: Lin2,
        }
        res = run(z0.ravel(), constraints + [ineq])
        limits_constrained = True
    Z = res.x.reshape(B1, n).copy()
    HZ = H @ Z
    return ReachSolution(
        coef=Z,
        q_rest=q_rest,
        basis=basis,
        cost=float(res.fun),
        effort=float(np.sum(Z * HZ * W)),
        hand_error=float(np.linalg.norm(eq_fun(res.x))),
        limits_constrained=limits_constrained,
        success=bool(res.success),
        n_iter=int(res.nit),
    )
