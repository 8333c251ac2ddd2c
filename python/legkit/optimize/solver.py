"""One small interface to a sparse NLP solver: IPOPT as bundled in the casadi wheel (pip alone installs it).

The NLP is given as NumPy callbacks (objective, gradient, constraints, Jacobian values on a fixed sparsity
pattern, and optionally the Hessian of the Lagrangian on its own pattern), which casadi carries to IPOPT through
`casadi.Callback`s, so every function of the robot stays in legkit's batched kernels; without a Hessian, IPOPT
approximates it by L-BFGS.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from legkit._extras import require
from legkit._validation import count, float_array, positive_scalar

Progress = Callable[[int, float, float], None]

#: IPOPT options of a primal-dual warm start (`solve(..., multipliers=)`): the start kept within 1e-6 of its bounds, a
#: small initial barrier parameter, and the adaptive barrier update, which leaves it where the start is already
#: central: the monotone update re-solves the barrier problem from mu_init down. The 16-interval amble plan
#: (`amble_plan_problem`, exact Hessian) from its 0.55 m/s optimum and multipliers: back onto itself in 2 iterations
#: against 35 (monotone); to 0.60 m/s (`continued`) in 53 against 92 (monotone; 97 with mu_init 1e-5, 203 with mu_init
#: and the pushes 1e-8), 82 and 85 with the pushes 1e-3 and 1e-4 (mu_init 1e-4, 1e-5), 51 with the loqo oracle, 228
#: with probing.
WARM_START = {"warm_start_init_point": "yes", "warm_start_bound_push": 1e-6, "warm_start_mult_bound_push": 1e-6, "mu_init": 1e-6,
              "mu_strategy": "adaptive"}


@dataclass
class NLP:
    """min f(x) s.t. x_lower <= x <= x_upper, g_lower <= g(x) <= g_upper, with the Jacobian of g given as
    values on the fixed pattern (jac_rows, jac_cols) (no duplicate entries), and optionally hessian(x,
    objective_factor, multipliers): the lower triangle of the Hessian of objective_factor f + multipliers . g on
    (hess_rows, hess_cols) (rows >= cols, no duplicates)."""

    x_lower: np.ndarray
    x_upper: np.ndarray
    g_lower: np.ndarray
    g_upper: np.ndarray
    objective: Callable[[np.ndarray], float]
    gradient: Callable[[np.ndarray], np.ndarray]
    constraints: Callable[[np.ndarray], np.ndarray]
    jacobian: Callable[[np.ndarray], np.ndarray]
    jac_rows: np.ndarray
    jac_cols: np.ndarray
    hessian: Callable[[np.ndarray, float, np.ndarray], np.ndarray] | None = None
    hess_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    hess_cols: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def n(self) -> int:
        return len(self.x_lower)

    @property
    def m(self) -> int:
        return len(self.g_lower)

    def violation(self, x: np.ndarray) -> float:
        """Largest violation of the bounds and constraints at x (0 when feasible)."""
        g = self.constraints(x)
        parts = [self.x_lower - x, x - self.x_upper, self.g_lower - g, g - self.g_upper]
        return float(max(np.max(p, initial=0.0) for p in parts))


@dataclass
class SolveResult:
    x: np.ndarray
    objective: float
    status: str
    success: bool
    iterations: int
    wall_time: float  # [s] of the whole solve
    evaluation_time: float  # [s] spent in the NLP callbacks (functions and Jacobians)
    violation: float  # largest bound/constraint violation at x
    history: list[tuple[int, float, float]] = field(default_factory=list)  # (iteration, objective, violation)
    best_feasible: tuple[int, float, np.ndarray] | None = None  # (iteration, objective, x) of the best iterate within tol
    tol: float = 1e-6
    multipliers: tuple[np.ndarray, np.ndarray] | None = None  # IPOPT's (bound, constraint) multipliers at x

    def after(self, first: SolveResult) -> SolveResult:
        """This result as the second stage of a continuation that began with `first`: iterations, times and
        history summed over both."""
        offset = len(first.history)
        history = first.history + [(i + offset, f, v) for i, f, v in self.history]
        best = None if self.best_feasible is None else (self.best_feasible[0] + offset,) + self.best_feasible[1:]
        return SolveResult(self.x, self.objective, self.status, self.success, first.iterations + self.iterations,
                           first.wall_time + self.wall_time, first.evaluation_time + self.evaluation_time, self.violation,
                           history, best, self.tol, self.multipliers)

    def best(self) -> tuple[np.ndarray, float]:
        """(x, objective) of the returned point if IPOPT succeeded or it is the best feasible one, else of the
        best iterate within the tolerance: on a nonsmooth objective (S_H jumps, eq. 10) IPOPT's iterates need
        not improve monotonically, and an iteration limit can stop it on a worse one."""
        final_is_best = self.violation <= self.tol and (self.best_feasible is None or self.objective <= self.best_feasible[1])
        if self.success or self.best_feasible is None or final_is_best:
            return self.x, self.objective
        return self.best_feasible[2], self.best_feasible[1]


class _Timer:
    """Times the callbacks and keeps the first exception raised in one, Ctrl-C's KeyboardInterrupt included: casadi
    would only report a failed evaluation, and IPOPT try a shorter step, so the iteration callback stops IPOPT
    once one is kept, and `solve` re-raises it after IPOPT returns."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.error: BaseException | None = None

    def __call__(self, function: Callable) -> Callable:
        def timed(*args: Any) -> Any:
            start = time.perf_counter()
            try:
                return function(*args)
            except BaseException as error:
                self.error = self.error or error
                raise
            finally:
                self.seconds += time.perf_counter() - start

        return timed


def solve(
    nlp: NLP, x0: np.ndarray, *, tol: float = 1e-6, max_iter: int = 3000, progress: Progress | None = None,
    options: dict | None = None, multipliers: tuple[np.ndarray, np.ndarray] | None = None, stall: tuple[int, float] | None = None,
    regularised_first: bool = False,
) -> SolveResult:
    """Solve `nlp` from x0 with IPOPT (MUMPS; the NLP's Hessian, or L-BFGS without one). progress(iteration, objective, violation) is
    called once per IPOPT iteration. options: extra IPOPT options (without the "ipopt." prefix). multipliers:
    (bound, constraint) multipliers to start from with x0, e.g. a neighbouring problem's
    `SolveResult.multipliers`: a primal-dual warm start with `WARM_START`'s options (options override them).
    stall (window, gain): stop (status "User_Requested_Stop") at an iterate whose objective is less than gain
    below that of the iterate window iterations before. regularised_first (with the NLP's Hessian): IPOPT factorises
    each KKT system first with the last iteration's Hessian regularisation (`_with_idle_variable`) rather than
    none, which saves a factorisation per iteration where the unregularised systems have the wrong inertia
    (`legkit.optimize.gaits.AMBLE_REGULARISED_FIRST`). The regularisation never reaches 0, so where they have the
    right inertia it costs exact Newton steps (IPOPT's default, False)."""
    require("casadi")
    import casadi as ca

    _single_threaded_blas(ca)
    x0 = float_array(x0, "x0", shape=(nlp.n,))
    positive_scalar(tol, "tol")
    count(max_iter, "max_iter", 0)
    start_duals = {}
    if multipliers is not None:
        lam_x, lam_g = (np.asarray(lam, dtype=np.float64) for lam in multipliers)
        if lam_x.shape != (nlp.n,) or lam_g.shape != (nlp.m,):
            raise ValueError(f"multipliers must have shapes ({nlp.n},) and ({nlp.m},), got {lam_x.shape} and {lam_g.shape}")
        start_duals = {"lam_x0": lam_x, "lam_g0": lam_g}
        options = {**WARM_START, **(options or {})}
    n_given = nlp.n
    if regularised_first and nlp.hessian is not None:
        nlp, x0 = _with_idle_variable(nlp), np.r_[x0, 0.0]
        if "lam_x0" in start_duals:
            start_duals["lam_x0"] = np.r_[start_duals["lam_x0"], 0.0]
    timer = _Timer()
    pattern = ca.Sparsity.triplet(nlp.m, nlp.n, nlp.jac_rows.tolist(), nlp.jac_cols.tolist())
    # casadi stores column-compressed; order our (row, col) values to match once.
    order = np.lexsort((nlp.jac_rows, nlp.jac_cols))
    objective, gradient = timer(nlp.objective), timer(nlp.gradient)
    constraints, jacobian = timer(nlp.constraints), timer(nlp.jacobian)
    n, m = nlp.n, nlp.m
    # casadi asks for f and g, and for the gradient and the Jacobian, in separate calls at one x.
    derivatives_at = _LastPoint(lambda x: [gradient(x), jacobian(x)[order]])
    values_at = _LastPoint(lambda x: [objective(x), constraints(x)])

    class Jacobian(ca.Callback):
        def __init__(self, name: str, opts: Mapping[str, Any]) -> None:
            ca.Callback.__init__(self)
            self.construct(name, opts)

        def get_n_in(self) -> int:
            return 3

        def get_n_out(self) -> int:
            return 2

        def get_sparsity_in(self, i: int) -> Any:
            return [ca.Sparsity.dense(n, 1), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(m, 1)][i]

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.dense(1, n) if i == 0 else pattern

        def has_eval_buffer(self) -> bool:
            return True

        def eval_buffer(self, arg: Any, res: Any) -> int:
            return _write(res, derivatives_at(_read(arg[0])))

    class Functions(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("legkit_nlp", {})

        def get_n_in(self) -> int:
            return 1

        def get_n_out(self) -> int:
            return 2

        def get_sparsity_in(self, i: int) -> Any:
            return ca.Sparsity.dense(n, 1)

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.dense(1, 1) if i == 0 else ca.Sparsity.dense(m, 1)

        def has_eval_buffer(self) -> bool:
            return True

        def eval_buffer(self, arg: Any, res: Any) -> int:
            return _write(res, values_at(_read(arg[0])))

        def has_jacobian(self) -> bool:
            return True

        # Without these casadi takes a callback's Jacobian as dense, and IPOPT factorises a dense KKT system.
        def has_jac_sparsity(self, oind: int, iind: int) -> bool:
            return True

        def get_jac_sparsity(self, oind: int, iind: int, symmetric: bool) -> Any:
            return ca.Sparsity.dense(1, n) if oind == 0 else pattern

        def get_jacobian(self, name: str, inames: Sequence[str], onames: Sequence[str], opts: Mapping[str, Any]) -> Any:
            self.jacobian_callback = Jacobian(name, opts)  # casadi holds a raw reference; keep it alive
            return self.jacobian_callback

    hessian = None
    if nlp.hessian is not None:  # casadi stores the upper triangle column-compressed: IPOPT's lower one transposed
        hessian_pattern = ca.Sparsity.triplet(n, n, nlp.hess_cols.tolist(), nlp.hess_rows.tolist())
        hessian_order = np.lexsort((nlp.hess_cols, nlp.hess_rows))
        curvature = timer(nlp.hessian)

        class Hessian(ca.Callback):
            def __init__(self) -> None:
                ca.Callback.__init__(self)
                self.construct("legkit_hessian", {})

            def get_n_in(self) -> int:
                return 4

            def get_n_out(self) -> int:
                return 1

            def get_name_in(self, i: int) -> str:
                return ["x", "p", "lam_f", "lam_g"][i]

            def get_name_out(self, i: int) -> str:
                return "triu_hess_gamma_x_x"

            def get_sparsity_in(self, i: int) -> Any:
                return [ca.Sparsity.dense(n, 1), ca.Sparsity(0, 1), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(m, 1)][i]

            def get_sparsity_out(self, i: int) -> Any:
                return hessian_pattern

            def has_eval_buffer(self) -> bool:
                return True

            def eval_buffer(self, arg: Any, res: Any) -> int:
                return _write(res, [curvature(_read(arg[0]), float(_read(arg[2])[0]), _read(arg[3]))[hessian_order]])

        hessian = Hessian()
    ipopt = {"tol": tol, "constr_viol_tol": tol, "max_iter": max_iter, "print_level": 0, "sb": "yes", "mu_strategy": "adaptive",
             # MUMPS with METIS ordering: the amble's constraint stage from the reference at seven speeds took 23-44
             # iterations (1.9-3.5 s) against 19-200+ (2.6-28+ s) with the default ordering.
             "mumps_pivot_order": 5, **({} if hessian is not None else {"hessian_approximation": "limited-memory"}), **(options or {})}
    state: dict = {}
    solver = _build(ca, nlp, ipopt, state, Functions(), hessian)
    history: list[tuple[int, float, float]] = []
    best: list[tuple[int, float, np.ndarray] | None] = [None]
    state.update(history=history, best=best, progress=progress, tol=tol, nlp=nlp, stall=stall, timer=timer)
    start = time.perf_counter()
    with _ctrl_c_kept(timer):
        result = solver(x0=x0, lbx=nlp.x_lower, ubx=nlp.x_upper, lbg=nlp.g_lower, ubg=nlp.g_upper, **start_duals)
    wall = time.perf_counter() - start
    if timer.error is not None:
        raise timer.error
    stats = solver.stats()
    x = np.asarray(result["x"]).ravel()
    kept = None if best[0] is None else (best[0][0], best[0][1], best[0][2][:n_given])
    return SolveResult(x[:n_given], float(result["f"]), stats["return_status"], bool(stats["success"]), int(stats["iter_count"]),
                       wall, timer.seconds, nlp.violation(x), history, kept, tol,
                       (np.asarray(result["lam_x"]).ravel()[:n_given], np.asarray(result["lam_g"]).ravel()))


def _with_idle_variable(nlp: NLP) -> NLP:
    """nlp with one more variable, free and in no function. IPOPT first factorises each KKT system unregularised
    and, at the wrong inertia, again with a regularisation; a system found singular unregularised in its first three
    iterations marks the Hessian structurally degenerate (Ipopt's PDPerturbationHandler, `hess_degenerate_`), after
    which every system is first factorised with the last regularisation times perturb_dec_fact. The idle
    variable's zero row makes the unregularised system singular; its own step and multiplier stay 0."""
    n = nlp.n

    def given(function: Callable) -> Callable:
        return lambda x, *args: function(x[:n], *args)

    return NLP(np.r_[nlp.x_lower, -np.inf], np.r_[nlp.x_upper, np.inf], nlp.g_lower, nlp.g_upper, given(nlp.objective),
               lambda x: np.r_[nlp.gradient(x[:n]), 0.0], given(nlp.constraints), given(nlp.jacobian), nlp.jac_rows, nlp.jac_cols,
               None if nlp.hessian is None else given(nlp.hessian), nlp.hess_rows, nlp.hess_cols)


@contextlib.contextmanager
def _ctrl_c_kept(timer: _Timer) -> Iterator[None]:
    """Ctrl-C during the solve is kept in `timer` rather than raised where it lands: casadi checks for signals between
    IPOPT's steps and, finding one, ends the solve as failed and drops the KeyboardInterrupt. Kept, it stops IPOPT at
    its next iteration and `solve` raises it. Only Python's own Ctrl-C handler, in the main thread, is replaced."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return

    def keep(signum: int, frame: Any) -> None:
        timer.error = timer.error or KeyboardInterrupt()

    signal.signal(signal.SIGINT, keep)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@functools.cache
def _single_threaded_blas(ca: Any) -> None:
    """Pin the OpenBLAS bundled with casadi (under IPOPT's MUMPS) to one thread. Its default, one thread per core,
    makes IPOPT's path depend on the machine's core count (the 4-interval amble: 416 iterations to S_H 0.2297 on one
    thread, 627 to 0.2141 on two), and on KKT systems this small the threads cost more than they give (43 against 78
    s of CPU there)."""
    from pathlib import Path

    for library in sorted(Path(ca.__file__).parent.glob("libcasadi-tp-openblas.so*")):
        ctypes.CDLL(str(library)).openblas_set_num_threads(1)
        return


def _read(buffer: Any) -> np.ndarray:
    """A copy of an input of a callback's copy-free interface (`eval_buffer`): casadi reuses its buffers."""
    return np.frombuffer(buffer, dtype=np.float64).copy()


def _write(buffers: Any, values: Sequence[Any]) -> int:
    """Write values into the output buffers of `eval_buffer` (nonzeros in casadi's column-major order), skipping
    the outputs casadi did not ask for. casadi's conversion of a NumPy array to a DM cost ~40 ms of CPU for the
    16-interval amble's 330,000 Hessian nonzeros, a quarter of evaluating them."""
    for buffer, value in zip(buffers, values):
        if buffer is not None and len(buffer):
            np.frombuffer(buffer, dtype=np.float64)[:] = value
    return 0


class _LastPoint:
    """`compute(x)`, kept for the last x it was asked at: asked again there, it returns the same outputs."""

    def __init__(self, compute: Callable[[np.ndarray], list[Any]]) -> None:
        self.compute = compute
        self.x: np.ndarray | None = None
        self.out: list[Any] = []

    def __call__(self, x: np.ndarray) -> list[Any]:
        if self.x is None or not np.array_equal(self.x, x):
            self.x, self.out = x, self.compute(x)
        return self.out


def _build(ca: Any, nlp: NLP, ipopt: dict, state: dict, functions: Any, hessian: Any) -> Any:
    """casadi's IPOPT solver of nlp from its callbacks (`functions`: f and g with their derivatives; `hessian`: the
    Hessian of the Lagrangian, or None); its iteration callback reports to `state` (history, best, progress), and
    stops IPOPT once `state`'s timer holds an exception."""
    n, m = nlp.n, nlp.m

    class Iteration(ca.Callback):
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.construct("legkit_iteration", {})

        def get_n_in(self) -> int:
            return ca.nlpsol_n_out()

        def get_n_out(self) -> int:
            return 1

        def get_name_in(self, i: int) -> str:
            return ca.nlpsol_out(i)

        def get_name_out(self, i: int) -> str:
            return "ret"

        def get_sparsity_in(self, i: int) -> Any:
            name = ca.nlpsol_out(i)
            if name == "f":
                return ca.Sparsity.scalar()
            if name in ("x", "lam_x"):
                return ca.Sparsity.dense(n)
            if name in ("g", "lam_g"):
                return ca.Sparsity.dense(m)
            return ca.Sparsity(0, 0)

        def has_eval_buffer(self) -> bool:
            return True

        def eval_buffer(self, arg: Any, res: Any) -> int:
            timer, stop = state["timer"], 1
            try:
                names = ca.nlpsol_out()
                f, g, x = (_read(arg[names.index(name)]) for name in ("f", "g", "x"))
                stop = self.stop(float(f[0]), g, x)
            except BaseException as error:  # Ctrl-C, or a progress hook that failed
                timer.error = timer.error or error
            return _write(res, [1 if timer.error is not None else stop])

        def stop(self, f: float, g: np.ndarray, x: np.ndarray) -> int:
            bounds, history, best = state["nlp"], state["history"], state["best"]
            viol = max(np.max(bounds.g_lower - g, initial=0.0), np.max(g - bounds.g_upper, initial=0.0),
                       np.max(bounds.x_lower - x, initial=0.0), np.max(x - bounds.x_upper, initial=0.0))
            history.append((len(history), f, float(viol)))
            if viol <= state["tol"] and (best[0] is None or f < best[0][1]):
                best[0] = (len(history) - 1, f, x)
            if state["progress"] is not None:
                state["progress"](len(history) - 1, f, float(viol))
            window = state["stall"]
            return int(window is not None and len(history) > window[0] and history[-1 - window[0]][1] - f < window[1])

    iteration = Iteration()
    symbol = ca.MX.sym("x", n)
    f_expr, g_expr = functions(symbol)
    extra = {} if hessian is None else {"hess_lag": hessian}
    solver = ca.nlpsol("legkit", "ipopt", {"x": symbol, "f": f_expr, "g": g_expr},
                       {"ipopt": ipopt, "print_time": False, "iteration_callback": iteration, "error_on_fail": False, **extra})
    solver.keep_alive = (iteration, functions, hessian)  # casadi holds raw references
    return solver
