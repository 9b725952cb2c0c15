"""Generalized ICP (Segal, Haehnel and Thrun, RSS 2009) with the covariances given, compiled.

small_gicp's GICP is the reference this follows step for step: plane-regularised covariances from
each point's k nearest (eigenvalues 1e-3, 1, 1), the residual of a source point against its nearest
target point weighted by the inverse of the two covariances' sum, the pose updated on the right by
the exponential of a Levenberg-Marquardt step, and its convergence test. What it adds is that the
covariances come from the caller. small_gicp 1.0.1's Python binding estimates a target's
covariances itself, from the target's points, at every registration and cannot be handed them
(``PointCloud`` has no setter), and that estimate was a third of a registration (31-60 ms for a
40-70 k point target). Here S(t) keeps each voxel's covariance as the mean of the covariances its
scans estimated where they were dense (:class:`~nbs_env.mapping.cloud.VoxelMeans` with
``covariances=True``), so a registration reads them and estimates only the rest. The nearest
neighbours still come from small_gicp's k-d tree.

The normal equations are summed in fixed runs of :data:`CHUNK` source points, the runs' sums then
added in order, whatever the number of threads computing them: the same inputs give the same pose,
bit for bit, on one core or many.
``tests/test_registration.py`` checks the covariances against small_gicp's ``estimate_covariances``
and an alignment against ``small_gicp.align`` on the same points.
"""

from __future__ import annotations

import numba
import numpy as np

from nbs_env import threads

__all__ = ["align", "covariances_from_neighbours", "jacobi", "smallest_eigenvector"]

#: small_gicp's Levenberg-Marquardt settings: the initial damping, its factor, the inner tries.
_LAMBDA = 1e-3
_LAMBDA_FACTOR = 10.0
_INNER = 10
#: Source points per run of the normal equations' sums (the unit of the threads' work).
CHUNK = 4096


@numba.njit(cache=True, nogil=True)
def jacobi(A: np.ndarray, V: np.ndarray) -> None:
    """Diagonalise the symmetric 3 x 3 ``A`` in place by cyclic Jacobi rotations (at most 12 sweeps,
    far more than a 3 x 3 needs); ``V`` receives the eigenvectors (columns, in the order of ``A``'s
    diagonal). The solver of :func:`smallest_eigenvector`, for the covariances and the plane normals."""
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    for _ in range(12):
        off = A[0, 1] * A[0, 1] + A[0, 2] * A[0, 2] + A[1, 2] * A[1, 2]
        if off <= 1e-30 * (A[0, 0] * A[0, 0] + A[1, 1] * A[1, 1] + A[2, 2] * A[2, 2]):
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = A[p, q]
            if apq == 0.0:
                continue
            theta = (A[q, q] - A[p, p]) / (2.0 * apq)
            t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            for k in range(3):
                akp, akq = A[k, p], A[k, q]
                A[k, p] = c * akp - s * akq
                A[k, q] = s * akp + c * akq
            for k in range(3):
                apk, aqk = A[p, k], A[q, k]
                A[p, k] = c * apk - s * aqk
                A[q, k] = s * apk + c * aqk
            for k in range(3):
                vkp, vkq = V[k, p], V[k, q]
                V[k, p] = c * vkp - s * vkq
                V[k, q] = s * vkp + c * vkq


def covariances_from_neighbours(points: np.ndarray, idx: np.ndarray, k: int) -> np.ndarray:
    """Plane-regularised covariances, as small_gicp's ``estimate_covariances``.

    Parameters
    ----------
    points : (p, 3) float
    idx : (n, K) int
        For each of n points, its nearest among ``points`` (itself included), -1 past the last.
    k : int
        How many of them to read (at most K).

    Returns
    -------
    (n, 3, 3) float
        V diag(1e-3, 1, 1) Vᵀ, V the eigenvectors of the neighbours' scatter (ascending
        eigenvalues): a flat disc along the local surface. The identity where fewer than five
        neighbours were found.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    out = np.zeros((idx.shape[0], 3, 3))

    def rows(part: slice) -> None:
        # Each point's covariance is its own: the runs write disjoint rows.
        _covariances(points, idx[part], int(k), out[part])

    threads.split(rows, len(idx), cost=20 * min(int(k), idx.shape[1]) * len(idx), interleave=False)
    return out


@numba.njit(cache=True, nogil=True)
def smallest_eigenvector(A: np.ndarray, V: np.ndarray) -> tuple[float, float, float]:
    """The eigenvector of the smallest eigenvalue of the symmetric 3 x 3 ``A`` (overwritten; ``V``
    is work space), by :func:`jacobi`. Also the plane normals' (:mod:`nbs_env.sensing.registration`)."""
    jacobi(A, V)
    m = 0
    if A[1, 1] < A[m, m]:
        m = 1
    if A[2, 2] < A[m, m]:
        m = 2
    return V[0, m], V[1, m], V[2, m]


@numba.njit(cache=True, nogil=True)
def _covariances(points: np.ndarray, idx: np.ndarray, k: int, out: np.ndarray) -> None:
    n = idx.shape[0]
    A = np.empty((3, 3))
    V = np.empty((3, 3))
    for i in range(n):
        count = 0
        sx = sy = sz = 0.0
        xx = xy = xz = yy = yz = zz = 0.0
        for j in range(min(k, idx.shape[1])):
            q = idx[i, j]
            if q < 0:
                break
            x, y, z = points[q, 0], points[q, 1], points[q, 2]
            sx += x
            sy += y
            sz += z
            xx += x * x
            xy += x * y
            xz += x * z
            yy += y * y
            yz += y * z
            zz += z * z
            count += 1
        if count < 5:
            out[i, 0, 0] = out[i, 1, 1] = out[i, 2, 2] = 1.0
            continue
        mx, my, mz = sx / count, sy / count, sz / count
        A[0, 0], A[0, 1], A[0, 2] = xx / count - mx * mx, xy / count - mx * my, xz / count - mx * mz
        A[1, 1], A[1, 2], A[2, 2] = yy / count - my * my, yz / count - my * mz, zz / count - mz * mz
        A[1, 0], A[2, 0], A[2, 1] = A[0, 1], A[0, 2], A[1, 2]
        v = smallest_eigenvector(A, V)
        # V diag(1e-3, 1, 1) Vᵀ = I - (1 - 1e-3) v vᵀ, v the eigenvector of the least eigenvalue.
        for a in range(3):
            for b in range(3):
                out[i, a, b] = (1.0 if a == b else 0.0) - (1.0 - 1e-3) * v[a] * v[b]


@numba.njit(cache=True, nogil=True)
def _inverse3(C: np.ndarray, M: np.ndarray) -> None:
    a, b, c = C[0, 0], C[0, 1], C[0, 2]
    d, e, f = C[1, 0], C[1, 1], C[1, 2]
    g, h, k = C[2, 0], C[2, 1], C[2, 2]
    m00, m10, m20 = e * k - f * h, f * g - d * k, d * h - e * g
    det = a * m00 + b * m10 + c * m20
    M[0, 0], M[0, 1], M[0, 2] = m00 / det, (c * h - b * k) / det, (b * f - c * e) / det
    M[1, 0], M[1, 1], M[1, 2] = m10 / det, (a * k - c * g) / det, (c * d - a * f) / det
    M[2, 0], M[2, 1], M[2, 2] = m20 / det, (b * g - a * h) / det, (a * e - b * d) / det


@numba.njit(cache=True, nogil=True)
def _residual(T, s, q):
    R, t = T[:3, :3], T[:3, 3]
    r0 = q[0] - (R[0, 0] * s[0] + R[0, 1] * s[1] + R[0, 2] * s[2] + t[0])
    r1 = q[1] - (R[1, 0] * s[0] + R[1, 1] * s[1] + R[1, 2] * s[2] + t[1])
    r2 = q[2] - (R[2, 0] * s[0] + R[2, 1] * s[1] + R[2, 2] * s[2] + t[2])
    return r0, r1, r2


@numba.njit(cache=True, nogil=True)
def _mahalanobis(M, r0, r1, r2) -> float:
    return (
        r0 * (M[0, 0] * r0 + M[0, 1] * r1 + M[0, 2] * r2)
        + r1 * (M[1, 0] * r0 + M[1, 1] * r1 + M[1, 2] * r2)
        + r2 * (M[2, 0] * r0 + M[2, 1] * r1 + M[2, 2] * r2)
    )


@numba.njit(cache=True)
def _linearize(T, source, source_covs, target, target_covs, idx, sq, max_sq, weights):
    """GICP's normal equations at ``T``: (H (6, 6), b (6,), error); ``weights`` (n, 3, 3) receives
    each matched point's inverse covariance (zero where unmatched) for :func:`_error`."""
    H = np.zeros((6, 6))
    g = np.zeros(6)
    err = 0.0
    R = T[:3, :3]
    C = np.empty((3, 3))
    RC = np.empty((3, 3))
    J = np.empty((3, 6))
    MJ = np.empty((3, 6))
    for i in range(len(source)):
        j = idx[i]
        if j < 0 or sq[i] > max_sq:
            weights[i] = 0.0
            continue
        s = source[i]
        r0, r1, r2 = _residual(T, s, target[j])
        for a in range(3):
            for b in range(3):
                RC[a, b] = (
                    R[a, 0] * source_covs[i, 0, b] + R[a, 1] * source_covs[i, 1, b] + R[a, 2] * source_covs[i, 2, b]
                )
        for a in range(3):
            for b in range(3):
                C[a, b] = target_covs[j, a, b] + RC[a, 0] * R[b, 0] + RC[a, 1] * R[b, 1] + RC[a, 2] * R[b, 2]
        M = weights[i]
        _inverse3(C, M)
        # d(residual)/d(rotation, translation), the pose perturbed on the right: [R [s]x, -R].
        for a in range(3):
            J[a, 0] = R[a, 1] * s[2] - R[a, 2] * s[1]
            J[a, 1] = R[a, 2] * s[0] - R[a, 0] * s[2]
            J[a, 2] = R[a, 0] * s[1] - R[a, 1] * s[0]
            J[a, 3], J[a, 4], J[a, 5] = -R[a, 0], -R[a, 1], -R[a, 2]
        for a in range(3):
            for c in range(6):
                MJ[a, c] = M[a, 0] * J[0, c] + M[a, 1] * J[1, c] + M[a, 2] * J[2, c]
        for c in range(6):
            for d in range(6):
                H[c, d] += J[0, c] * MJ[0, d] + J[1, c] * MJ[1, d] + J[2, c] * MJ[2, d]
            g[c] += MJ[0, c] * r0 + MJ[1, c] * r1 + MJ[2, c] * r2
        err += 0.5 * _mahalanobis(M, r0, r1, r2)
    return H, g, err


@numba.njit(cache=True)
def _error(T, source, target, idx, weights) -> float:
    """The error at ``T`` of the matches and weights of the last :func:`_linearize`."""
    err = 0.0
    for i in range(len(source)):
        if weights[i, 0, 0] == 0.0 and weights[i, 1, 1] == 0.0:
            continue
        r0, r1, r2 = _residual(T, source[i], target[idx[i]])
        err += 0.5 * _mahalanobis(weights[i], r0, r1, r2)
    return err


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _se3_exp(a: np.ndarray) -> np.ndarray:
    """The rigid transform of the twist ``a`` = (rotation vector, translation), as small_gicp's."""
    w, v = a[:3], a[3:]
    theta2 = float(w @ w)
    theta = np.sqrt(theta2)
    out = np.eye(4)
    W = _skew(w)
    if theta < 1e-10:
        out[:3, :3] = np.eye(3) + W
        out[:3, 3] = out[:3, :3] @ v
        return out
    out[:3, :3] = np.eye(3) + np.sin(theta) / theta * W + (1.0 - np.cos(theta)) / theta2 * (W @ W)
    V = np.eye(3) + (1.0 - np.cos(theta)) / theta2 * W + (theta - np.sin(theta)) / (theta2 * theta) * (W @ W)
    out[:3, 3] = V @ v
    return out


def align(
    nearest,
    target: np.ndarray,
    target_covs: np.ndarray,
    source: np.ndarray,
    source_covs: np.ndarray,
    start: np.ndarray,
    max_distance: float,
    max_iterations: int,
    epsilon: float,
) -> np.ndarray:
    """GICP of ``source`` onto ``target`` from ``start``: the (4, 4) pose.

    Parameters
    ----------
    nearest : callable
        ``nearest(world) -> (index, squared distance)`` of the nearest target point to each of the
        (m, 3) points (index -1 where none): small_gicp's k-d tree of ``target``.
    target, source : (n, 3) float
        Points; the source in its own frame.
    target_covs, source_covs : (n, 3, 3) float
        Their covariances (:func:`covariances_from_neighbours`).
    start : (4, 4) float
        The initial pose (source frame to target frame).
    max_distance : float
        Matches farther apart than this are left out, metres.
    max_iterations : int
        Outer iterations (each one new matches and a Levenberg-Marquardt step).
    epsilon : float
        Converged when a step turns less than this (rad) and moves less than this (m).
    """
    source = np.ascontiguousarray(source, dtype=float)
    T = np.asarray(start, dtype=float).copy()
    weights = np.zeros((len(source), 3, 3))
    damping = _LAMBDA
    for _ in range(max_iterations):
        idx, sq = nearest(source @ T[:3, :3].T + T[:3, 3])
        H, g, err = _linearize(T, source, source_covs, target, target_covs, idx, sq, max_distance**2, weights)
        for _inner in range(_INNER):
            step = np.linalg.solve(H + damping * np.eye(6), -g)
            moved = T @ _se3_exp(step)
            if _error(moved, source, target, idx, weights) < err:
                T = moved
                damping /= _LAMBDA_FACTOR
                break
            damping *= _LAMBDA_FACTOR
        else:
            return T  # no step lowers the error: a minimum
        if np.linalg.norm(step[:3]) < epsilon and np.linalg.norm(step[3:]) < epsilon:
            return T
    return T
