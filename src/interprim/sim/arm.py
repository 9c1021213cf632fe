"""Planar serial arms: forward kinematics, analytic Jacobians, inverse kinematics.

The simulated high-five of the paper (Sec. IV, Fig. 5) uses two opposing planar
arms.  Both are instances of :class:`PlanarArm`, a chain of revolute (hinge)
joints in the x-y plane (x: horizontal, towards the partner; y: up; metres and
radians).

Kinematics of an arm with link lengths ``l_1..l_n``, base point ``b``, base
direction ``theta_0`` and orientation sign ``s`` (``+1`` normal, ``-1``
mirrored)::

    a_i   = theta_0 + s * (q_1 + ... + q_i)          absolute angle of link i
    p_i   = b + sum_{k<=i} l_k [cos a_k, sin a_k]     end point of link i
    dp_n/dq_j = s * sum_{i>=j} l_i [-sin a_i, cos a_i]   (Jacobian column j)

The mirror sign lets the controlled arm, which faces the observed arm from the
other side, use the same joint conventions: for both arms a positive shoulder
angle raises the arm and a positive elbow angle bends the forearm upwards
("elbow down", like a human arm reaching up and forward).
"""

from __future__ import annotations

import numpy as np

__all__ = ["PlanarArm", "observed_arm", "controlled_arm"]


class PlanarArm:
    """A planar chain of hinge joints.

    Parameters
    ----------
    link_lengths : sequence of float
        Length of each link in metres, from the base outwards; one joint per link
        (joint ``i`` sits at the start of link ``i``).
    base : (2,) sequence of float
        Position of the first joint (the shoulder) in metres.
    base_angle : float
        Direction (radians, from +x, counter-clockwise) of the first link when
        all joint angles are zero.
    mirror : bool
        If True, joint angles turn clockwise (``s = -1``) so that a mirrored arm
        has the same joint conventions as a normal one.
    joint_limits : array_like, shape (n, 2)
        Lower and upper limit of each joint angle, radians.
    rest : array_like, shape (n,)
        Rest posture (start of every movement), radians.
    joint_names : sequence of str, optional
        Names of the joints, for plots and reports.
    name : str
        Name of the arm.
    """

    def __init__(
        self,
        link_lengths,
        base=(0.0, 0.0),
        base_angle: float = 0.0,
        mirror: bool = False,
        joint_limits=None,
        rest=None,
        joint_names=None,
        name: str = "arm",
    ):
        self.link_lengths = np.asarray(link_lengths, dtype=float).reshape(-1)
        if self.link_lengths.size < 1 or np.any(self.link_lengths <= 0):
            raise ValueError(f"link_lengths must be positive, got {self.link_lengths.tolist()}")
        n = self.link_lengths.size
        self.base = np.asarray(base, dtype=float).reshape(2)
        self.base_angle = float(base_angle)
        self.mirror = bool(mirror)
        self.sign = -1.0 if self.mirror else 1.0
        if joint_limits is None:
            joint_limits = np.tile([-np.pi, np.pi], (n, 1))
        self.joint_limits = np.asarray(joint_limits, dtype=float).reshape(n, 2)
        if np.any(self.joint_limits[:, 0] >= self.joint_limits[:, 1]):
            raise ValueError(f"joint_limits must have lower < upper, got {self.joint_limits.tolist()}")
        self.rest = np.zeros(n) if rest is None else np.asarray(rest, dtype=float).reshape(n)
        self.joint_names = list(joint_names) if joint_names is not None else [f"q{i + 1}" for i in range(n)]
        if len(self.joint_names) != n:
            raise ValueError(f"joint_names must have {n} entries, got {len(self.joint_names)}")
        self.name = str(name)

    # ------------------------------------------------------------------ basics
    @property
    def n_joints(self) -> int:
        """Number of hinge joints (= number of links)."""
        return self.link_lengths.size

    @property
    def reach(self) -> float:
        """Maximal distance of the hand from the base, metres."""
        return float(self.link_lengths.sum())

    def __repr__(self) -> str:
        return (
            f"PlanarArm(name={self.name!r}, links={self.link_lengths.tolist()}, base={self.base.tolist()}, "
            f"joints={self.joint_names})"
        )

    def _check_q(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape[-1:] != (self.n_joints,):
            raise ValueError(f"q must have shape (..., {self.n_joints}) for arm {self.name!r}, got {q.shape}")
        return q

    def link_angles(self, q) -> np.ndarray:
        """Absolute angle ``a_i`` of every link, shape ``(..., n)``."""
        q = self._check_q(q)
        return self.base_angle + self.sign * np.cumsum(q, axis=-1)

    # -------------------------------------------------------------- kinematics
    def forward_kinematics(self, q) -> np.ndarray:
        """Positions of the base and of every link end point.

        Parameters
        ----------
        q : array_like, shape (..., n)
            Joint angles, radians (any leading batch shape).

        Returns
        -------
        points : ndarray, shape (..., n + 1, 2)
            ``points[..., 0, :]`` is the base, ``points[..., i, :]`` the end of
            link ``i``; the last one is the hand.
        """
        a = self.link_angles(q)
        seg = self.link_lengths[:, None] * np.stack([np.cos(a), np.sin(a)], axis=-1)  # (..., n, 2)
        pts = np.cumsum(seg, axis=-2) + self.base
        base = np.broadcast_to(self.base, pts.shape[:-2] + (1, 2))
        return np.concatenate([base, pts], axis=-2)

    def hand(self, q) -> np.ndarray:
        """Hand (end-effector) position, shape ``(..., 2)``."""
        a = self.link_angles(q)
        x = self.base[0] + np.sum(self.link_lengths * np.cos(a), axis=-1)
        y = self.base[1] + np.sum(self.link_lengths * np.sin(a), axis=-1)
        return np.stack([x, y], axis=-1)

    def jacobian(self, q) -> np.ndarray:
        """Analytic Jacobian of the hand position with respect to the joint angles.

        Parameters
        ----------
        q : array_like, shape (..., n)

        Returns
        -------
        J : ndarray, shape (..., 2, n)
            ``J[..., r, j] = d hand_r / d q_j``.
        """
        a = self.link_angles(q)
        dx = -self.link_lengths * np.sin(a)
        dy = self.link_lengths * np.cos(a)
        # column j sums links i >= j: reverse cumulative sum
        jx = np.flip(np.cumsum(np.flip(dx, -1), axis=-1), -1)
        jy = np.flip(np.cumsum(np.flip(dy, -1), axis=-1), -1)
        return self.sign * np.stack([jx, jy], axis=-2)

    def hand_and_jacobian(self, q):
        """Hand position ``(..., 2)`` and Jacobian ``(..., 2, n)`` in one pass (for optimisers)."""
        a = self.link_angles(q)
        lc = self.link_lengths * np.cos(a)
        ls = self.link_lengths * np.sin(a)
        cx = np.cumsum(lc[..., ::-1], axis=-1)[..., ::-1]  # sum over links i >= j
        cy = np.cumsum(ls[..., ::-1], axis=-1)[..., ::-1]
        hand = np.empty(a.shape[:-1] + (2,))
        hand[..., 0] = self.base[0] + cx[..., 0]
        hand[..., 1] = self.base[1] + cy[..., 0]
        J = np.empty(a.shape[:-1] + (2, a.shape[-1]))
        J[..., 0, :] = -self.sign * cy
        J[..., 1, :] = self.sign * cx
        return hand, J

    def within_limits(self, q, tol: float = 1e-9) -> bool:
        """True if every joint angle in ``q`` (any batch shape) lies within the limits (+- ``tol``)."""
        q = self._check_q(q)
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        return bool(np.all(q >= lo - tol) and np.all(q <= hi + tol))

    def inverse_kinematics(
        self, goal, q0=None, q_pref=None, reg: float = 1e-3, tol: float = 1e-10, polish: bool = True
    ):
        """Joint angles that put the hand at ``goal``, within the joint limits.

        Solves ``min_q ||hand(q) - goal||^2 + reg * ||q - q_pref||^2`` subject to
        the joint limits with :func:`scipy.optimize.least_squares` (trust-region
        reflective, analytic Jacobian).  The small regulariser picks one solution
        of a redundant arm (the one closest to ``q_pref``); it is switched off in
        a second polishing solve so that the hand error is limited only by
        ``tol``.

        Parameters
        ----------
        goal : (2,) array_like
            Target hand position, metres.
        q0 : (n,) array_like, optional
            Initial guess (default: ``q_pref``).
        q_pref : (n,) array_like, optional
            Preferred posture for redundancy resolution (default: middle of the
            joint ranges).
        reg : float
            Weight of the preference term (rad^-2 m^2).
        tol : float
            Tolerance passed to ``least_squares`` (``xtol``, ``ftol``, ``gtol``).
        polish : bool
            Run the second, unregularised solve (default True).  ``False`` gives
            a cheap initial guess whose hand error is of the order of
            ``reg * ||q - q_pref||``.

        Returns
        -------
        q : ndarray, shape (n,)
            Joint angles, radians (the best reachable ones if ``goal`` is out of reach).
        """
        from scipy.optimize import least_squares

        goal = np.asarray(goal, dtype=float).reshape(2)
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        if q_pref is None:
            q_pref = 0.5 * (lo + hi)
        q_pref = np.asarray(q_pref, dtype=float).reshape(self.n_joints)
        x0 = np.clip(q_pref if q0 is None else np.asarray(q0, dtype=float), lo + 1e-9, hi - 1e-9)
        sr = np.sqrt(reg)

        def res(q):
            return np.concatenate([self.hand(q) - goal, sr * (q - q_pref)])

        def jac(q):
            return np.vstack([self.jacobian(q), sr * np.eye(self.n_joints)])

        sol = least_squares(res, x0, jac=jac, bounds=(lo, hi), method="trf", xtol=tol, ftol=tol, gtol=tol)
        q = sol.x
        if polish and reg > 0:
            # polish: pure position error, started from the regularised solution
            sol2 = least_squares(
                lambda q: self.hand(q) - goal,
                np.clip(q, lo + 1e-12, hi - 1e-12),
                jac=self.jacobian,
                bounds=(lo, hi),
                method="trf",
                xtol=tol,
                ftol=tol,
                gtol=tol,
            )
            q = sol2.x
        return q


def observed_arm() -> PlanarArm:
    """The observed agent of the high-five (paper Fig. 5, left): two links, two hinge joints.

    Modelled joints: a shoulder hinge at the base (0, 0) and an elbow hinge
    between upper arm (0.70 m) and forearm (0.65 m).  Zero angles point the arm
    horizontally towards the partner (+x); positive shoulder angle raises it,
    positive elbow angle bends the forearm upwards.  Rest posture: arm hanging
    down and slightly forward.
    """
    return PlanarArm(
        link_lengths=[0.70, 0.65],
        base=(0.0, 0.0),
        base_angle=0.0,
        mirror=False,
        joint_limits=[[-1.8, 1.9], [0.0, 2.6]],
        rest=[-1.65, 0.35],
        joint_names=["shoulder", "elbow"],
        name="observed",
    )


def controlled_arm() -> PlanarArm:
    """The controlled agent of the high-five (paper Fig. 5, right): three links, three hinge joints.

    Modelled joints: shoulder hinge at the base (1.6, 0), elbow hinge between
    upper arm (0.55 m) and forearm (0.50 m), wrist hinge between forearm and hand
    (0.25 m).  The arm is mirrored to face the observed arm (zero angles point
    it horizontally towards -x) and shares its joint conventions: positive
    shoulder angle raises it, positive elbow/wrist angles bend upwards.

    The paper's text says "three links and two joints"; we model a hinge at
    each of the three links (shoulder, elbow, wrist), which makes the arm
    redundant for a 2-D hand position, as a robot arm usually is.
    """
    return PlanarArm(
        link_lengths=[0.55, 0.50, 0.25],
        base=(1.6, 0.0),
        base_angle=np.pi,
        mirror=True,
        joint_limits=[[-1.8, 1.9], [0.0, 2.6], [-1.3, 1.3]],
        rest=[-1.65, 0.35, 0.20],
        joint_names=["shoulder", "elbow", "wrist"],
        name="controlled",
    )
