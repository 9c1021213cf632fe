"""The conditioning methods of :class:`~interprim.models.coupling.CouplingModel`, one small type each.

Every method predicts ``mu_y + sum_i alpha_i (y_i - mu_y)``, a linear smoother of the training rows (Eq. 18 of Ben
Amor et al., ICRA 2014, with the prefix observation model of :mod:`interprim.models.coupling`).  A
:class:`Conditioner` gives the row weights ``alpha`` ``(Q, R)`` of a batch of ``Q`` queries from a
:class:`Context`: the centred training rows and queries of one training set, shared by every candidate (what more
than one candidate needs -- the rows' SVD, the query-row distances, the joint PCA -- is computed once, on first use).

======================  =====================================================================================
:class:`Mean`           ``"mean"``: the prior mean (no coupling), ``alpha = 0``
:class:`Ridge`          ``"ridge"``: the sample covariance with Eq. 16's noise ``sigma^2 = lambda tr(S_xx) / p``
:class:`PPCA`           ``"ppca"``: a probabilistic-PCA (reduced-rank) joint covariance of rank ``r``
:class:`Kernel`         ``"kernel"``: Gaussian weights of the distance between prefixes (relative bandwidth)
:class:`Blend`          ``"blend"``: ``w ridge + (1 - w) kernel`` (model averaging of two linear smoothers)
======================  =====================================================================================

A conditioner is made from the ``(method, param)`` a model file stores by :func:`conditioner`.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

__all__ = ["Context", "Conditioner", "Mean", "Ridge", "PPCA", "Kernel", "Blend", "CONDITIONERS", "conditioner",
           "target_block", "centre_rows_np"]


def target_block(P, Ydc, R):
    """``P L / b`` (R x rank C): the target block of :class:`PPCA`'s ``Z``, with ``C = Ydc Ydc^T = L L^T``
    (eigenpairs of the demonstrations' Gram matrix, rank ``<= n_u - 1``) and ``b^2 = tr(P C P^T) / R``."""
    ec, Vc = np.linalg.eigh(Ydc @ Ydc.T)
    b2 = max(float(np.sum(np.sum(Ydc * Ydc, axis=1) * P.sum(axis=0))) / R, 1e-300)
    kc = ec > 1e-12 * max(float(ec[-1]), 1e-300)
    return P @ (Vc[:, kc] * (np.sqrt(ec[kc]) / math.sqrt(b2)))


def centre_rows_np(X, x, Xc, xc, nrm, qnrm) -> float:
    """The rows ``X`` (R, p) and queries ``x`` (Q, p) centred by the rows' mean into ``Xc`` and ``xc``, each
    centred row's squared norm into ``nrm`` (R,) and each query's into ``qnrm`` (Q,) (skipped when they are
    empty); returns ``sum(Xc ** 2)``: what :class:`Context` reads of its rows (``Context.of``'s centring, the trace
    of :meth:`Context.gram`, the norms of :meth:`Context.distances`).  The numpy reference of the compiled
    ``prefix_rows.centre_rows_into`` (the same numbers)."""
    mu = X.mean(axis=0)
    np.subtract(X, mu, out=Xc)
    np.subtract(x, mu, out=xc)
    if nrm.size == X.shape[0]:
        nrm[...] = np.sum(Xc**2, axis=1)
    if qnrm.size == x.shape[0]:
        qnrm[...] = np.sum(xc**2, axis=1)
    return float(np.sum(Xc * Xc))


def _median_rows(d2: np.ndarray) -> np.ndarray:
    """``numpy.median(d2, axis=1, keepdims=True)`` of finite ``d2`` (Q, R): the same partition and the same mean of
    the two middle values, without the wrapper's checks (called once per streamed frame)."""
    R = d2.shape[1]
    k = R // 2
    if R % 2:
        return np.partition(d2, k, axis=1)[:, k:k + 1]
    part = np.partition(d2, (k - 1, k), axis=1)
    return (part[:, k - 1:k] + part[:, k:k + 1]) / 2.0


_LAPACK: dict = {}


def _cho_solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``cho_solve(cho_factor(A, lower=True), B)`` of a symmetric positive definite float64 ``A`` (overwritten) by
    LAPACK's ``potrf`` / ``potrs`` themselves, the routines scipy's wrappers call, without their checks (``A`` and
    ``B`` are finite here by construction); a clear error when ``A`` is not positive definite."""
    if not _LAPACK:
        from scipy.linalg.lapack import get_lapack_funcs

        _LAPACK["potrf"], _LAPACK["potrs"] = get_lapack_funcs(("potrf", "potrs"), (np.zeros((1, 1)),))
    c, info = _LAPACK["potrf"](A, lower=1, overwrite_a=1, clean=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"the ridge's Gram matrix is not positive definite (potrf info {info})")
    x, info = _LAPACK["potrs"](c, B, lower=1)
    if info != 0:
        raise ValueError(f"potrs: illegal argument {-info}")
    return x


class Context:
    """What every conditioner of one training set and one batch of queries shares; the base fields can also be
    read as a mapping (``ctx["Xc"]``, ``dict(ctx)``).

    Parameters
    ----------
    Xc : ndarray, shape (R, p)
        The training rows, centred (grouped by demonstration, every demonstration with the same number of rows).
    xc : ndarray, shape (Q, p)
        The queries, centred by the rows' mean.
    P : ndarray, shape (R, n)
        The group indicator: ``P[i, j] = 1`` when row ``i`` belongs to demonstration ``j``.
    ybar : ndarray, shape (q,)
        The demonstrations' mean target.
    Ydc : ndarray, shape (n, q)
        The demonstrations' centred targets.
    ylow : ndarray, optional
        :func:`target_block` of ``P`` and ``Ydc`` when the caller has it (it does not depend on the phase).
    sq : tuple, optional
        ``(sum(Xc ** 2), sum(Xc ** 2, axis=1) or None, sum(xc ** 2, axis=1) or None)`` when the caller has them
        (:func:`centre_rows_np` or its compiled kernel: the same numbers as the context's own).
    """

    FIELDS: ClassVar[tuple[str, ...]] = ("R", "Xc", "xc", "P", "ybar", "Ydc")

    def __init__(self, Xc: np.ndarray, xc: np.ndarray, P: np.ndarray, ybar: np.ndarray, Ydc: np.ndarray,
                 ylow: np.ndarray | None = None, sq: tuple | None = None):
        self.R = Xc.shape[0]
        self.Xc, self.xc, self.P, self.ybar, self.Ydc, self.ylow = Xc, xc, P, ybar, Ydc, ylow
        self._sq = sq
        self._svd: tuple | None = None
        self._gram: tuple | None = None
        self._distances: tuple | None = None
        self._pca: tuple | None = None

    @classmethod
    def of(cls, X: np.ndarray, groups: np.ndarray, Ydemo: np.ndarray, x: np.ndarray) -> Context:
        """The context of rows ``X`` (R, p) of demonstrations ``groups`` (R,), the demonstrations' targets ``Ydemo``
        (n, q) and queries ``x`` (Q, p)."""
        R = X.shape[0]
        mu = X.mean(axis=0)
        ug, inv = np.unique(groups, return_inverse=True)
        P = np.zeros((R, ug.size))
        P[np.arange(R), inv] = 1.0
        Yd = Ydemo[ug]
        ybar = Yd.mean(axis=0)
        return cls(X - mu, x - mu, P, ybar, Yd - ybar)

    @classmethod
    def from_mapping(cls, m) -> Context:
        """A context from a mapping with the base fields (and optionally ``"ylow"``)."""
        return m if isinstance(m, Context) else cls(m["Xc"], m["xc"], m["P"], m["ybar"], m["Ydc"], m.get("ylow"))

    def keys(self):
        """The base fields' names (with :meth:`__getitem__`, ``dict(ctx)`` works)."""
        return self.FIELDS

    def __getitem__(self, name: str):
        if name not in self.FIELDS:
            raise KeyError(name)
        return getattr(self, name)

    def svd(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(U, S, xc V)`` of the thin SVD ``Xc = U S V^T`` (computed once)."""
        if self._svd is None:
            U, S, Vt = np.linalg.svd(self.Xc, full_matrices=False)
            self._svd = (U, S, self.xc @ Vt.T)
        return self._svd

    def gram(self) -> tuple[np.ndarray, float]:
        """``(A, tr)``: the smaller Gram matrix of the rows, ``X_c^T X_c`` (p x p) when ``p <= R`` else
        ``X_c X_c^T`` (R x R), and its trace ``sum(X_c^2)`` (computed once)."""
        if self._gram is None:
            Xc = self.Xc
            A = Xc.T @ Xc if Xc.shape[1] <= Xc.shape[0] else Xc @ Xc.T
            self._gram = (A, float(np.sum(Xc * Xc)) if self._sq is None else self._sq[0])
        return self._gram

    def distances(self) -> tuple[np.ndarray, np.ndarray]:
        """``(d2, med)``: squared distances (Q, R) of the queries to the rows and each query's median (computed
        once)."""
        if self._distances is None:
            xc, Xc = self.xc, self.Xc
            if self._sq is not None and self._sq[1] is not None and self._sq[2] is not None:
                nrm, qnrm = self._sq[1], self._sq[2]
            else:
                nrm, qnrm = np.sum(Xc**2, axis=1), np.sum(xc**2, axis=1)
            d2 = (qnrm[:, None] + nrm[None, :] - 2.0 * xc @ Xc.T)
            d2 = np.maximum(d2, 0.0)
            self._distances = (d2, np.maximum(_median_rows(d2), 1e-300))
        return self._distances

    def pca(self) -> tuple:
        """``(a, Z, V, S, U, dim)``: the joint PCA of :class:`PPCA` (computed once; see there)."""
        if self._pca is None:
            R, Xc, P, Ydc = self.R, self.Xc, self.P, self.Ydc
            p = Xc.shape[1]
            a2 = max((float(np.sum(Xc**2)) if self._sq is None else self._sq[0]) / R, 1e-300)
            # the target block P L / b of Z below (the caller may pass it: it depends on the training rows' grouping
            # and the demonstrations only, not on the phase or the query)
            PLb = self.ylow if self.ylow is not None else target_block(P, Ydc, R)
            # The rows' Gram matrix Xc Xc^T / a2 + P C P^T / b2 (R x R) is Z Z^T with Z = [Xc / a, P L / b] and
            # C = Ydc Ydc^T = L L^T: its eigenpairs come from the (p + rank C)-square Z^T Z = V diag(S^2) V^T
            # (U = Z V / S), the same SVD of [Xc / a, Yc / b] at a fraction of the cost (R = n_demos x n_jitter rows).
            a = math.sqrt(a2)
            Z = np.concatenate([Xc / a, PLb], axis=1)
            if Z.shape[0] <= Z.shape[1]:  # fewer rows than columns (no jitter): the rows' own Gram matrix
                e, U = np.linalg.eigh(Z @ Z.T)
                e, U = e[::-1], U[:, ::-1]
                keep = e > 1e-12 * max(float(e[0]), 1e-300)
                U, S = U[:, keep], np.sqrt(e[keep])
                V = (Z.T @ U) / S  # right singular vectors
            else:
                e, V = np.linalg.eigh(Z.T @ Z)
                e, V = e[::-1], V[:, ::-1]
                keep = e > 1e-12 * max(float(e[0]), 1e-300)
                V, S, U = V[:, keep], np.sqrt(e[keep]), None  # U = Z V / S, formed for the r columns used
            # x block of the right singular vectors: V[:p] (Z^T U = V S and the x block of Z^T U S^-1 is Vx^T)
            self._pca = (a, Z, V, S, U, Ydc.shape[1] + p)
        return self._pca


class Conditioner:
    """One conditioning method with its hyper-parameter: the row weights of Eq. 18 for its covariance model.

    Subclasses set ``name`` (the method's name in :data:`CONDITIONERS`, in ``selection_`` and in model files) and
    implement :meth:`weights`; ``param`` is what a model file stores.
    """

    name: ClassVar[str] = ""

    def __init__(self, param: Any = None):
        self.param = param

    @property
    def key(self) -> tuple[str, Any]:
        """``(name, param)``, as ``CouplingModel.method_`` / ``param_`` and a model file hold them."""
        return self.name, self.param

    def weights(self, ctx: Context) -> np.ndarray:  # pragma: no cover - interface
        """Row weights ``alpha`` (Q, R): the prediction is ``ybar + sum_i alpha_i (y_i - ybar)``."""
        raise NotImplementedError

    def predict(self, ctx: Context) -> tuple[np.ndarray, np.ndarray]:
        """Mean (Q, q) and leverage ``h`` (Q,) of the linear smoother (module docstring of
        :mod:`interprim.models.coupling`: ``h = sum_j (sum_{i in demo j} alpha_i + 1/N)^2``)."""
        mean, G = self._mean(ctx)
        G += 1.0 / ctx.P.shape[1]  # the weights of the mean itself
        return mean, np.sum(G**2, axis=1)

    def mean(self, ctx: Context) -> np.ndarray:
        """The mean of :meth:`predict` alone (the same numbers), for a caller that does not read the leverage."""
        return self._mean(ctx)[0]

    def _mean(self, ctx: Context) -> tuple[np.ndarray, np.ndarray]:
        """``(mean (Q, q), G (Q, n))``: the smoother's mean and each demonstration's sum of its rows' weights."""
        G = self.weights(ctx) @ ctx.P  # per demonstration: the sum of its rows' weights
        return ctx.ybar + G @ ctx.Ydc, G

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.param!r})"


class Mean(Conditioner):
    """The prior mean: no coupling (``alpha = 0``)."""

    name = "mean"

    def weights(self, ctx: Context) -> np.ndarray:
        """Zeros (Q, R)."""
        return np.zeros((ctx.xc.shape[0], ctx.R))


class Ridge(Conditioner):
    """Eq. 18 with the sample covariance and the noise ``sigma^2 = lambda tr(S_xx) / p`` of Eq. 16 as the
    regulariser (ridge regression from the prefix to the trajectories); ``param`` is ``lambda``.

    ``mu_y|x - mu_y = S_yx (S_xx + sigma^2 I)^-1 (x - mu_x)`` with ``S_yx = Y_c^T X_c / R``, i.e.
    ``alpha = X_c (S_xx + sigma^2 I)^-1 (x - mu_x) / R``.
    """

    name = "ridge"

    def weights(self, ctx: Context) -> np.ndarray:
        """``alpha`` (Q, R) on the row space of ``X_c``: ``x_c V diag(S / (S^2 + R sigma^2)) U^T`` with the thin
        SVD ``X_c = U S V^T``, i.e. ``x_c (X_c^T X_c + R sigma^2 I)^-1 X_c^T`` (``= x_c X_c^T (X_c X_c^T +
        R sigma^2 I)^-1``), solved by a Cholesky factorisation of the smaller Gram matrix (:meth:`Context.gram`):
        the same weights up to rounding (the ridge keeps the system well conditioned: ``cond <= 1 + p /
        lambda``) at a fraction of an SVD's cost; the SVD when ``sigma^2 = 0``."""
        R = ctx.R
        A, tr = ctx.gram()
        c = float(self.param) * tr / ctx.Xc.shape[1]  # R sigma^2 = lambda tr(X_c^T X_c) / p
        if not (c > 0.0 and np.isfinite(c)):
            U, S, xv = ctx.svd()
            sigma2 = float(self.param) * float(np.sum(S**2)) / (R * ctx.Xc.shape[1])  # lambda tr(S_xx) / p
            return (xv * (S / (S**2 + R * sigma2))) @ U.T
        A = A.copy()
        A.reshape(-1)[:: A.shape[0] + 1] += c  # the diagonal (a view of the fresh copy)
        if A.shape[0] == ctx.Xc.shape[1]:  # p <= R: (Q, p) solves, then onto the rows
            return _cho_solve(A, ctx.xc.T).T @ ctx.Xc.T
        return _cho_solve(A, (ctx.xc @ ctx.Xc.T).T).T


class Kernel(Conditioner):
    """A locally weighted conditioning: the demonstrations' trajectories averaged with Gaussian weights of the
    distance between their prefixes and the observed one; ``param`` is the bandwidth relative to the root median
    squared distance (``-> inf``: the mean, ``-> 0``: the nearest neighbour)."""

    name = "kernel"

    def weights(self, ctx: Context) -> np.ndarray:
        """Normalised Gaussian weights minus ``1/R`` (Q, R)."""
        d2, med = ctx.distances()
        logw = -0.5 * d2 / (float(self.param) ** 2 * med)
        w = np.exp(logw - logw.max(axis=1, keepdims=True))
        return w / w.sum(axis=1, keepdims=True) - 1.0 / ctx.R


class PPCA(Conditioner):
    """The reduced-rank (probabilistic PCA) joint Gaussian conditioning; ``param`` is the rank ``r``.

    The joint covariance of ``z = [x / a, y / b]`` (each block scaled to unit total variance) is
    ``W W^T + diag(s_x^2 I, s_y^2 I)`` with ``W`` the first ``rank`` principal directions scaled by
    ``sqrt(lambda_k - s^2)`` (Tipping & Bishop's ML solution; ``s_x^2`` = the x block's variance the directions
    leave unexplained, per dimension).  Eq. 18 then gives ``mu_y + W_y (W_x^T W_x + s_x^2 I)^-1 W_x^T (x - mu_x)``,
    a linear combination of the centred training rows (``W_y = Y_c^T U_r diag(sqrt(lambda - s^2) / S_r) / b``).
    """

    name = "ppca"

    def weights(self, ctx: Context) -> np.ndarray:
        """``alpha`` (Q, R) through an ``r x r`` solve on the joint PCA (:meth:`Context.pca`)."""
        R, Xc, xc = ctx.R, ctx.Xc, ctx.xc
        p = Xc.shape[1]
        a, Z, V, S, U, dim = ctx.pca()
        r = int(min(int(self.param), max(S.size - 1, 1)))
        lam = S**2 / R
        Vx = V[:p, :r].T  # (r, p)
        sig2 = float(lam[r:].sum()) / max(dim - r, 1)
        scale = np.sqrt(np.maximum(lam[:r] - sig2, 0.0))
        Wx = Vx.T * scale  # (p, r)
        sx2 = max((1.0 - float(np.sum(Wx**2))) / p, 1e-12)
        m = np.linalg.solve(Wx.T @ Wx + sx2 * np.eye(r), Wx.T @ (xc.T / a))  # (r, Q) latent means
        coef = (scale / np.maximum(S[:r], 1e-300))[:, None] * m
        if U is None:  # U_r = Z V_r / S_r folded in
            return (Z @ (V[:, :r] @ (coef / S[:r, None]))).T
        return (U[:, :r] @ coef).T


class Blend(Conditioner):
    """``w`` times a ridge plus ``1 - w`` times a kernel conditioning (model averaging of two linear smoothers);
    ``param`` is ``(lambda, bandwidth, w)``."""

    name = "blend"

    def __init__(self, param: tuple):
        lam, bw, w = param
        super().__init__((lam, bw, w))
        self.ridge, self.kernel, self.w = Ridge(lam), Kernel(bw), w

    def weights(self, ctx: Context) -> np.ndarray:
        """``w alpha_ridge + (1 - w) alpha_kernel``."""
        return self.w * self.ridge.weights(ctx) + (1.0 - self.w) * self.kernel.weights(ctx)


#: every conditioning method by its name
CONDITIONERS: dict[str, type[Conditioner]] = {c.name: c for c in (Mean, Ridge, PPCA, Kernel, Blend)}


def conditioner(method: str, param: Any = None) -> Conditioner:
    """The conditioner of a ``(method, param)`` pair (``CouplingModel.method_`` / ``param_``, a model file)."""
    try:
        cls = CONDITIONERS[method]
    except KeyError:
        raise ValueError(f"unknown coupling method {method!r}; expected one of {sorted(CONDITIONERS)}") from None
    return cls(param)
