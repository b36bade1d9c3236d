"""The normal matrix of a calibration by the Schur complement of its nuisance block: solves, the log determinant
and the hat matrix's blocks at a cost linear in the rows.

The unknowns are the free parameters (the first ``n_par`` columns of the Jacobian ``J = [J_p J_n]``) and the
nuisance increments (the rest). A row of ``J_n`` touches only its own instance's unknowns (or the two instances a
certified length links, a frame and its markers), so the nuisance block ``D = J_n^T J_n`` of the normal matrix
``A = J^T J + diag(damping)`` is block diagonal by the connected components of its pattern; with
``B = J_p^T J_n``, ``W = D^-1 B^T`` (nuisance x parameters) and the Schur complement ``S = A_pp - B W``
(parameters x parameters)::

    A^-1 b = [S^-1 (b_p - B D^-1 b_n);  D^-1 b_n - W x_p]       log det A = log det D + log det S
    H = J A^-1 J^T:   H_ik = g_i S^-1 g_k^T + j_ni D^-1 j_nk^T,  g_i = j_pi - j_ni W

(``j_pi``, ``j_ni`` row i's parameter and nuisance parts). The second term of ``H_ik`` is 0 unless rows i and k
touch the same component. A nuisance unknown that meets many others (a reference instrument's frame, which every
nest seen in it meets: :data:`HUB_DEGREE`) is taken with the parameters (in ``p`` above), so that no component
grows with the rows; up to :data:`calibration.solver.DENSE_UNKNOWNS` unknowns every one is (``A`` dense, one LU).
Every quantity costs the rows times the parameters squared plus the components' sizes cubed, where the LU of ``A``
with a dense right-hand side over every unknown (:class:`calibration.solver.NormalFactor`) costs the rows times the
unknowns, which grow with the rows.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from arm_model import NumericalError

from .solver import SINGULAR, NormalFactor, dense_enough

__all__ = ["BlockNormal", "ROW_CHUNK", "HUB_DEGREE"]

#: a nuisance unknown whose column meets more than this many others in the normal matrix (a reference instrument's
#: frame, which every nest or marker seen in it meets) joins the parameters in the Schur complement, so that the
#: nuisance block keeps small components (one a nest, not one of every nest and the frame)
HUB_DEGREE = 64

#: rows whose parameter part ``g`` is held at once (rows x parameters doubles): bounds the memory of a leverage
ROW_CHUNK = 20000


class BlockNormal:
    """``A = J^T J + diag(damping)`` of the (column-scaled) Jacobian ``j`` (rows x unknowns, sparse or dense) whose
    first ``n_par`` columns are the parameters, factored by the Schur complement of the nuisance block (module
    docstring). Raises :class:`NumericalError` when ``A`` is exactly singular.

    Attributes:
        j: the Jacobian (CSR); n_par; damping: (unknowns,) the diagonal added.
    """

    def __init__(self, j, n_par: int, damping: np.ndarray | float = 0.0) -> None:
        self.j = sp.csr_matrix(j)
        self.n_par = int(n_par)
        n = self.j.shape[1]
        self.damping = np.array(np.broadcast_to(np.asarray(damping, dtype=float), (n,)))
        if dense_enough(n):                 # few unknowns: every one dense (LAPACK beats scipy.sparse's overhead)
            hub = np.arange(self.n_par, n)
        else:
            jn = self.j[:, self.n_par:].tocsc()
            hub = self.n_par + np.flatnonzero(np.diff((jn.T @ jn).tocsc().indptr) > HUB_DEGREE)
        self._dense = np.concatenate([np.arange(self.n_par), hub]).astype(int)
        self._rest = np.setdiff1d(np.arange(self.n_par, n), hub)
        p = len(self._dense)
        self._jn: sp.csr_matrix | None = None               # None: no nuisance block (every unknown dense)
        self._logdet_d = 0.0
        if len(self._rest):
            jp = self._jp = self.j[:, self._dense].toarray()
            self._jn = self.j[:, self._rest].tocsr()
            self._dinv, self._logdet_d = _block_inverse(self._jn.T @ self._jn + sp.diags(self.damping[self._rest]))
            self._bt = np.asarray(self._jn.T @ jp)                       # B^T (nuisance x parameters)
            self._w = np.asarray(self._dinv @ self._bt)                 # W = D^-1 B^T
            s = jp.T @ jp - self._bt.T @ self._w
        else:
            jp = self._jp = self.j.toarray()
            s = jp.T @ jp
        s.flat[:: p + 1] += self.damping[self._dense]
        self._s = NormalFactor(0.5 * (s + s.T)) if p else None

    def _solve_s(self, b: np.ndarray) -> np.ndarray:
        return self._s.solve(b) if self._s is not None else b

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``A^-1 b`` for a vector or a matrix of columns ``b``."""
        b = np.asarray(b, dtype=float)
        if self._jn is None:
            return self._solve_s(b)
        y = self._dinv @ b[self._rest]
        xp = self._solve_s(b[self._dense] - self._bt.T @ y)
        x = np.empty_like(b)
        x[self._dense], x[self._rest] = xp, y - self._w @ xp
        return x

    def log_abs_det(self) -> float:
        """``log |det A| = log |det D| + log |det S|``."""
        s = 0.0 if self._s is None else self._s.log_abs_det()
        return self._logdet_d + s

    def _rows(self, rows) -> tuple[np.ndarray, sp.csr_matrix | None]:
        """``(j_p, j_n)`` of ``rows``: indices into the rows of ``j``, or Jacobian rows (CSR over every unknown);
        ``j_n`` None without a nuisance block."""
        if _indices(rows):
            return self._jp[rows], None if self._jn is None else self._jn[rows]
        rows = sp.csr_matrix(rows)
        if self._jn is None:
            return rows.toarray(), None
        return rows[:, self._dense].toarray(), rows[:, self._rest].tocsr()

    def parts(self, rows) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix | None, sp.csr_matrix | None]:
        """``(g, g S^-1, j_n D^-1, j_n)`` of ``rows`` (indices into the rows of ``j``, or Jacobian rows: CSR over every
        unknown): ``H_ik = g_i S^-1 g_k^T + (j_n D^-1)_i j_nk^T`` (the last two None without a nuisance block)."""
        jp, jn = self._rows(rows)
        if jn is None:
            return jp, self._solve_s(jp.T).T, None, None
        g = jp - np.asarray(jn @ self._w)
        return g, self._solve_s(g.T).T, (jn @ self._dinv).tocsr(), jn

    def leverage(self, rows=None) -> np.ndarray:
        """The diagonal of ``R A^-1 R^T`` for the rows ``R`` (indices into the rows of ``j``, default all: their
        leverages; or Jacobian rows, CSR over every unknown), :data:`ROW_CHUNK` rows at a time."""
        if rows is None:
            rows = np.arange(self.j.shape[0])
        elif not _indices(rows):
            rows = sp.csr_matrix(rows)
        h = np.empty(rows.shape[0])
        for s in range(0, rows.shape[0], ROW_CHUNK):
            g, gs, y, jn = self.parts(rows[s: s + ROW_CHUNK])
            h[s: s + ROW_CHUNK] = np.einsum("ij,ij->i", g, gs)
            if y is not None:
                h[s: s + ROW_CHUNK] += np.asarray(y.multiply(jn).sum(axis=1)).ravel()
        return h

    def without(self, rows: np.ndarray) -> BlockNormal:
        """The normal matrix of the same fit without the rows ``rows`` (``A - J_O^T J_O``)."""
        keep = np.ones(self.j.shape[0], dtype=bool)
        keep[rows] = False
        return BlockNormal(self.j[keep], self.n_par, self.damping)


def _indices(rows) -> bool:
    """Whether ``rows`` are row indices (an integer vector) rather than Jacobian rows."""
    return isinstance(rows, np.ndarray) and rows.ndim == 1 and rows.dtype.kind in "iu"


def _block_inverse(d: sp.spmatrix) -> tuple[sp.csr_matrix, float]:
    """``(D^-1, log |det D|)`` of a symmetric sparse ``d`` that is block diagonal by the connected components of its
    pattern: each component's dense block inverted (LAPACK, the components of one size together)."""
    n = d.shape[0]
    if n == 0:
        return sp.csr_matrix((0, 0)), 0.0
    d = sp.coo_matrix(d)
    count, label = connected_components(d, directed=False)
    order = np.argsort(label, kind="stable")
    size = np.bincount(label, minlength=count)
    start = np.concatenate([[0], np.cumsum(size)])
    local = np.empty(n, dtype=int)
    local[order] = np.arange(n) - start[label[order]]
    rows, cols, vals, logdet = [], [], [], 0.0
    for m in np.unique(size):
        comps = np.flatnonzero(size == m)
        slot = np.full(count, -1)
        slot[comps] = np.arange(len(comps))
        idx = order[start[comps][:, None] + np.arange(m)]             # (components, m) their columns
        sel = slot[label[d.row]] >= 0
        blocks = np.zeros((len(comps), m, m))
        np.add.at(blocks, (slot[label[d.row[sel]]], local[d.row[sel]], local[d.col[sel]]), d.data[sel])
        sign, logabs = np.linalg.slogdet(blocks)
        if np.any(sign == 0):
            raise NumericalError(SINGULAR.format("a nuisance block"))
        logdet += float(np.sum(logabs))
        inv = np.linalg.inv(blocks)
        rows.append(np.broadcast_to(idx[:, :, None], inv.shape).ravel())
        cols.append(np.broadcast_to(idx[:, None, :], inv.shape).ravel())
        vals.append(inv.ravel())
    dinv = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    return dinv, logdet
