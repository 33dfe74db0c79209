"""Trust-region least squares from many starts at once: the algorithm of ``scipy.optimize.least_squares`` with
``method="trf"`` and no bounds (the exact trust-region subproblem by one SVD of the Jacobian, linear loss, unit
``x_scale``, the default tolerances), followed step for step on every start, the residual evaluations of all the
starts still running gathered into one call per round. scipy has no batched least-squares solver; the tests hold
this one equal to ``least_squares`` from the same starts.

Parameters and residuals are in the caller's units; nothing here knows of frames.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from scipy.linalg import get_lapack_funcs, svd

EPS = np.finfo(float).eps
TOL = 1e-8
"""``ftol``, ``xtol`` and ``gtol`` of ``least_squares`` (its defaults)."""


def norm(v: np.ndarray) -> float:
    """The Euclidean norm of a vector, as ``numpy.linalg.norm`` computes it (the root of ``v . v``)."""
    return math.sqrt(v.dot(v))


@functools.lru_cache(maxsize=16)
def _gesdd(m: int, n: int):
    """LAPACK's ``gesdd`` as ``scipy.linalg.svd`` picks it for an (m,n) float matrix, and its work size."""
    gesdd, gesdd_lwork = get_lapack_funcs(("gesdd", "gesdd_lwork"), (np.zeros((1, 1)),), ilp64="preferred")
    work, info = gesdd_lwork(m, n, compute_uv=True, full_matrices=False)
    return gesdd, (int(work.real) if info == 0 else None)


def thin_svd(J: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``scipy.linalg.svd(J, full_matrices=False)``: the same LAPACK call, without its checks on every call (the
    checked one where LAPACK reports a problem, to raise its error)."""
    gesdd, lwork = _gesdd(*J.shape)
    if lwork is not None and J.dtype == np.float64:
        U, s, Vt, info = gesdd(J, compute_uv=True, lwork=lwork, full_matrices=False, overwrite_a=False)
        if info == 0:
            return U, s, Vt
    return svd(J, full_matrices=False)


def trust_region_step(uf: np.ndarray, s: np.ndarray, V: np.ndarray, Delta: float, alpha: float,
                      rtol: float = 0.01, max_iter: int = 10) -> tuple[np.ndarray, float]:
    """The step ``p`` minimising ``|J p + f|`` within ``|p| <= Delta`` from ``J = U diag(s) V^T`` and ``uf = U^T f``
    (More's method on one SVD, as scipy's ``solve_lsq_trust_region``), and the Levenberg-Marquardt parameter
    ``alpha`` it ends at (``alpha`` in: the previous one, a first guess)."""
    n, m = len(s), len(uf)
    suf = s * uf
    s2, suf2 = s**2, suf**2  # the squares every evaluation of phi reads, computed once
    full_rank = bool(m >= n and s[-1] > EPS * m * s[0])
    if full_rank:
        p = -V.dot(uf / s)
        if norm(p) <= Delta:
            return p, 0.0
    alpha_upper = norm(suf) / Delta
    alpha_lower = 0.0
    if full_rank:
        phi, phi_prime = _phi(0.0, suf, suf2, s2, Delta)
        alpha_lower = -phi / phi_prime
    if not full_rank and alpha == 0:
        alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
    for _ in range(max_iter):
        if alpha < alpha_lower or alpha > alpha_upper:
            alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
        phi, phi_prime = _phi(alpha, suf, suf2, s2, Delta)
        if phi < 0:
            alpha_upper = alpha
        ratio = phi / phi_prime
        alpha_lower = max(alpha_lower, alpha - ratio)
        alpha -= (phi + Delta) * ratio / Delta
        if abs(phi) < rtol * Delta:
            break
    p = -V.dot(suf / (s2 + alpha))
    p *= Delta / norm(p)
    return p, alpha


def _phi(alpha: float, suf: np.ndarray, suf2: np.ndarray, s2: np.ndarray, Delta: float) -> tuple[float, float]:
    """The norm of the step regularised by ``alpha`` less ``Delta``, and its derivative in ``alpha`` (``suf2``, ``s2``:
    the squares of ``suf`` and of the singular values)."""
    denom = s2 + alpha
    p_norm = norm(suf / denom)
    return p_norm - Delta, -(suf2 / denom**3).sum() / p_norm


def _radius(Delta: float, actual: float, predicted: float, step_norm: float, bound_hit: bool):
    """The next trust radius and the ratio of the actual to the predicted reduction of the cost."""
    if predicted > 0:
        ratio = actual / predicted
    elif predicted == actual == 0:
        ratio = 1
    else:
        ratio = 0
    if ratio < 0.25:
        Delta = 0.25 * step_norm
    elif ratio > 0.75 and bound_hit:
        Delta *= 2.0
    return Delta, ratio


def _one_start(x0: np.ndarray, f: np.ndarray, J: np.ndarray, max_nfev: int):
    """One start's iterations as a generator: it yields ``("eval", x)`` and is sent the residuals ``f`` at ``x``,
    yields ``("jac",)`` and is sent the Jacobian at its last accepted ``x`` (only when it iterates on from there: a
    rejected step, or a start that stops, needs none), and yields ``("iter", nit, cost, x)`` after each iteration
    and is sent whether to stop there; it returns its ``x``."""
    x, nfev, Delta, alpha = x0.copy(), 1, norm(x0), 0.0
    Delta = 1.0 if Delta == 0 else Delta
    cost = 0.5 * np.dot(f, f)
    done, iteration = False, 0
    while True:
        if J is None:  # a step was accepted: its Jacobian, unless the start stops there
            if done or nfev == max_nfev:
                return x
            J = yield ("jac",)
        g = J.T.dot(f)
        done = done or np.abs(g).max() < TOL
        if done or nfev == max_nfev:
            return x
        U, s, V = thin_svd(J)
        V, uf = V.T, U.T.dot(f)
        actual = -1
        while actual <= 0 and nfev < max_nfev:
            step, alpha = trust_region_step(uf, s, V, Delta, alpha)
            Js = J.dot(step)
            predicted = -(0.5 * np.dot(Js, Js) + np.dot(step, g))
            x_new = x + step
            f_new = yield ("eval", x_new)
            nfev += 1
            step_norm = norm(step)
            if not np.isfinite(f_new).all():
                Delta = 0.25 * step_norm
                continue
            cost_new = 0.5 * np.dot(f_new, f_new)
            actual = cost - cost_new
            Delta_new, ratio = _radius(Delta, actual, predicted, step_norm, step_norm > 0.95 * Delta)
            done = (actual < TOL * cost and ratio > 0.25) or step_norm < TOL * (TOL + norm(x))
            if done:
                break
            alpha *= Delta / Delta_new
            Delta = Delta_new
        if actual > 0:
            x, f, J, cost = x_new, f_new, None, cost_new
        iteration += 1
        if (yield ("iter", iteration, cost, x)):
            return x


def jacobian(J, rows) -> np.ndarray:
    """The Jacobians (k',m,n) at rows ``rows`` (k',) of one residual call's points: ``J`` the call's (k,m,n)
    Jacobians, or a callable giving those of the rows asked (computed only when asked)."""
    return J(rows) if callable(J) else np.asarray(J)[rows]


Halt = Callable[[int, int, float], "bool | None"]
"""``halt(start, nit, cost)``: whether a start stops after iteration ``nit`` at ``cost`` (``least_squares``'
callback raising ``StopIteration``); None while that is not known yet (it may depend on other starts' answers:
the start runs on, and the question is asked again, in order, for every iteration it passed meanwhile)."""


def least_squares_many(fun: Callable, X0: np.ndarray, max_nfev: int, halt: Halt | None = None,
                       done: Callable[[int, np.ndarray], None] | None = None) -> np.ndarray:
    """``least_squares(method="trf")`` from every row of ``X0`` (B,n): (B,n) the answers. ``fun(idx, X)`` gives
    the residuals (k,m) of starts ``idx`` (k,) at ``X`` (k,n), all at once, and their Jacobians: (k,m,n), or a
    callable ``jac(rows)`` giving the (k',m,n) Jacobians of the rows ``rows`` (k',) of ``X`` when they are needed
    (``jacobian``): only where a step is accepted and the start iterates on. ``halt``: see ``Halt``;
    ``done(start, x)`` is told each start's answer once it is final (starts in any order)."""
    X0 = np.asarray(X0, float)
    F0, J0 = fun(np.arange(len(X0)), X0)
    if not np.all(np.isfinite(F0)):
        raise ValueError("Residuals are not finite in the initial point.")
    J0 = jacobian(J0, np.arange(len(X0)))
    gens = [_one_start(x, f, J, max_nfev) for x, f, J in zip(X0, F0, J0, strict=True)]
    run = _Runs(len(X0), halt, done)
    req = {i: _send(g, None, run, i) for i, g in enumerate(gens)}  # a start already optimal returns at once
    last: dict[int, tuple] = {}  # each start's latest residual call: its Jacobians and the start's row there
    while True:
        for i in [i for i in req if not run.halted(i)]:
            r = req[i]
            while r is not None and r[0] == "iter" and not run.halted(i):
                r = run.ask(i, r, gens[i])
            req[i] = r
        req = {i: r for i, r in req.items() if r is not None and not run.halted(i)}
        for i, J in _jacobians([i for i in sorted(req) if req[i][0] == "jac"], last):
            if not run.halted(i):
                req[i] = _send(gens[i], J, run, i)
        req = {i: r for i, r in req.items() if r is not None and not run.halted(i)}
        if not req:
            break
        idx = sorted(req)
        F, J = fun(np.array(idx), np.array([req[i][1] for i in idx]))
        for k, i in enumerate(idx):
            if not run.halted(i):
                last[i] = (J, k)
                req[i] = _send(gens[i], F[k], run, i)
    run.settle()
    return run.answers()


def _jacobians(starts: list[int], last: dict[int, tuple]):
    """``(start, J)`` for each of ``starts`` at its latest residual call (``last``), one ``jacobian`` per call."""
    calls: dict[int, list[int]] = {}
    for i in starts:
        calls.setdefault(id(last[i][0]), []).append(i)
    for group in calls.values():
        Js = jacobian(last[group[0]][0], np.array([last[i][1] for i in group]))
        yield from zip(group, Js, strict=True)


def _send(gen, value, run: _Runs, i: int):
    """``gen.send(value)``, or None once the start has returned (its answer then handed to ``run``)."""
    try:
        return gen.send(value)
    except StopIteration as stop:
        run.finish(i, stop.value)
        return None


class _Runs:
    """The starts' answers and the iterations whose stop is not decided yet (``Halt``)."""

    def __init__(self, B: int, halt: Halt | None, done):
        self.halt, self.done = halt, done
        self.x: list = [None] * B
        self.pending: list[list] = [[] for _ in range(B)]
        self.final = [False] * B
        self.stopped = [False] * B

    def ask(self, i: int, req: tuple, gen):
        """Answer one ``("iter", ...)`` request of start ``i``; its next request, or None when it stopped."""
        _, nit, cost, x = req
        if self.halt is not None and not self.pending[i]:
            stop = self.halt(i, nit, cost)
            if stop:
                self.stopped[i], self.x[i] = True, x
                self.settle()
                return None
            if stop is None:
                self.pending[i].append((nit, cost, x.copy()))
        elif self.halt is not None:
            self.pending[i].append((nit, cost, x.copy()))
        return _send(gen, False, self, i)

    def finish(self, i: int, x: np.ndarray) -> None:
        """Start ``i`` returned ``x`` (ignored once a stop decided later has ended it)."""
        if self.stopped[i]:
            return
        self.x[i] = x
        self.settle()

    def halted(self, i: int) -> bool:
        """Whether start ``i`` was stopped by ``halt``."""
        return self.stopped[i]

    def settle(self) -> None:
        """Decide, start by start in order, the stops asked earlier; hand on the answers that are final."""
        for i in range(len(self.x)):
            while self.pending[i]:
                nit, cost, x = self.pending[i][0]
                stop = self.halt(i, nit, cost)
                if stop is None:
                    break
                if stop:
                    self.pending[i].clear()
                    self.stopped[i] = True
                    self.x[i] = x
                    break
                self.pending[i].pop(0)
            if self.x[i] is not None and not self.pending[i] and not self.final[i]:
                self.final[i] = True
                if self.done is not None:
                    self.done(i, self.x[i])

    def answers(self) -> np.ndarray:
        """(B,n) every start's final answer."""
        if not all(self.final):
            raise RuntimeError("least_squares_many: a stop was never decided (halt kept answering None)")
        return np.array(self.x)
