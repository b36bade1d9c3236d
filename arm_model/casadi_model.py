"""The CasADi evaluator: ``f(q, w, p)`` as SX expressions from the same chain code.

``p`` is the named parameter vector of :mod:`arm_model.params` (errors added to the description),
which calibration identifies. Inputs and outputs of the Function are named. :class:`NumpyFunction` calls a
CasADi Function on numpy arrays without CasADi's matrix conversions (what calibration evaluates in its loops).
"""
from __future__ import annotations

import threading
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .chain import ball_centre_expr
from .description import ArmDescription
from .params import param_spec, split_params

__all__ = ["casadi_ball_centre", "NumpyFunction"]


def _ops() -> SimpleNamespace:
    import casadi as ca
    return SimpleNamespace(sin=ca.sin, cos=ca.cos, sign=ca.sign)


def casadi_ball_centre(desc: ArmDescription, name: str = "ball_centre") -> Any:
    """CasADi Function ``ball_centre(q[J], w[6], p[P]) -> (p_base[3])`` [m].

    ``w`` is the wrench at the ball in the probe frame (force [N], then torque [N m]).
    """
    import casadi as ca

    spec = param_spec(desc)
    q = ca.SX.sym("q", desc.n_joints)
    w = ca.SX.sym("w", 6)
    p = ca.SX.sym("p", spec.size)
    rows, p_last, compliance = split_params(desc, p)
    x, y, z = ball_centre_expr(desc.convention, rows, p_last, compliance,
                               [q[i] for i in range(desc.n_joints)], [w[i] for i in range(6)], _ops(),
                               desc.chain_joints, desc.probe.rotation, desc.probe.lever)
    return ca.Function(name, [q, w, p], [ca.vertcat(x, y, z)], ["q", "w", "p"], ["p_base"])


class NumpyFunction:
    """A CasADi Function called on numpy arrays through its buffer (``Function.buffer``): the inputs are read
    and the outputs written in place, column-major, with none of the conversions to and from CasADi matrices
    a plain call makes (on a mapped Function of thousands of points they cost twice the evaluation itself).

    ``f(*args)`` returns the outputs as C-ordered float arrays of the Function's output shapes, sparse outputs
    with their structural zeros written: the same arrays as ``np.asarray`` of a plain call's outputs, bit for
    bit. An input is a numpy array of the input's shape, or one that a plain call would repeat to it: a vector
    of the right length as a row or a column, a block of whole columns repeated side by side (a mapped
    Function's shared input, e.g. the parameter vector), or a scalar. Safe to share between threads (one
    evaluation at a time)."""

    def __init__(self, fn: Any) -> None:
        self.fn = fn
        for i in range(fn.n_in()):
            if not fn.sparsity_in(i).is_dense():
                raise ValueError(f"{fn.name()}: input {fn.name_in(i)} is not dense")
        self._in_shapes = [tuple(fn.size_in(i)) for i in range(fn.n_in())]
        self._out = [self._output_layout(fn.sparsity_out(i)) for i in range(fn.n_out())]
        self._buffer: Any = None
        self._lock = threading.Lock()

    @staticmethod
    def _output_layout(sparsity: Any) -> tuple[tuple[int, int], int, np.ndarray | None]:
        """(shape, nonzeros, their flat column-major positions in the dense output, None when it is dense)."""
        shape = (int(sparsity.size1()), int(sparsity.size2()))
        if sparsity.is_dense():
            return shape, shape[0] * shape[1], None
        colind, row = (np.asarray(v, dtype=np.int64) for v in sparsity.get_ccs())
        col = np.repeat(np.arange(shape[1], dtype=np.int64), np.diff(colind))
        return shape, len(row), col * shape[0] + row

    def __getstate__(self) -> dict[str, Any]:
        return {"fn": self.fn}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["fn"])  # type: ignore[misc]

    def _input(self, i: int, a: ArrayLike) -> np.ndarray:
        """Input ``i`` as the contiguous column-major nonzeros the buffer reads."""
        a = np.asarray(a, dtype=float)
        r, c = self._in_shapes[i]
        if a.size == r * c and (a.ndim < 2 or r == 1 or c == 1):
            a = a.reshape(r, c)
        elif a.ndim < 2:
            a = a.reshape(-1, 1)
        if a.shape != (r, c):
            if a.size == 1:
                a = np.full((r, c), a.item())
            elif a.shape[0] == r and a.shape[1] and c % a.shape[1] == 0:
                a = np.tile(a, (1, c // a.shape[1]))
            else:
                raise ValueError(f"{self.fn.name()}: input {self.fn.name_in(i)} has shape {a.shape}, "
                                 f"expected {(r, c)}")
        return np.ascontiguousarray(a.reshape(-1, order="F"))

    def __call__(self, *args: ArrayLike) -> tuple[np.ndarray, ...]:
        if len(args) != len(self._in_shapes):
            raise ValueError(f"{self.fn.name()}: {len(args)} inputs, expected {len(self._in_shapes)}")
        ins = [self._input(i, a) for i, a in enumerate(args)]
        nzs = [np.empty(nnz) for _, nnz, _ in self._out]
        with self._lock:
            if self._buffer is None:
                self._buffer = self.fn.buffer()
            buf, evaluate = self._buffer
            for i, a in enumerate(ins):
                buf.set_arg(i, memoryview(a))  # type: ignore[arg-type]
            for i, a in enumerate(nzs):
                buf.set_res(i, memoryview(a))  # type: ignore[arg-type]
            evaluate()
            status = buf.ret()
        if status != 0:
            raise RuntimeError(f"{self.fn.name()}: CasADi evaluation failed (return code {status})")
        out = []
        for (shape, _, where), nz in zip(self._out, nzs, strict=True):
            if where is not None:
                dense = np.zeros(shape[0] * shape[1])
                dense[where] = nz
                nz = dense
            out.append(np.ascontiguousarray(nz.reshape(shape, order="F")))
        return tuple(out)
