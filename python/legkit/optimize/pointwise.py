"""The exact constraint Jacobian and Hessian of the Lagrangian of a `Transcription`, assembled point by point.

casadi's own derivatives of the NLP expanded into one SX graph evaluate on casadi's virtual machine: the
amble's Hessian of the Lagrangian is 2.45 M instructions, 11-13 ms per evaluation, and with the Jacobian a
third of the solve's wall time (docs/optimize.md). Every constraint piece is one small function F mapped over
many points (`Mapped`), so its derivatives are too: the Jacobian of F and the Hessian of mu . F are derived
once per piece, compiled to C (cached on disk, see `compile_functions`), mapped over the points and
scattered into the NLP's patterns by constant sparse matrices. A point's multipliers mu are the rows'
multipliers through the piece's selection (selection^T lambda). Linear rows add constant Jacobian entries
and no curvature; the objective's Hessian is casadi's of the expanded objective.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.sparse import coo_matrix
from tqdm import tqdm

from legkit.optimize.symbolic import Mapped, casadi_sparse, gather

if TYPE_CHECKING:
    from legkit.optimize.symbolic import Transcription

#: A piece is compiled when its Jacobian and Hessian would cost at least this many virtual-machine instructions per
#: evaluation (points x instructions, ~5 ns each): the amble then compiles 20 pieces (30 s on two cores, once).
COMPILE_ABOVE = 20_000
#: Compiler flags: gcc -Og compiled the amble's RNEA-residual Hessian (200 points) in 2.2 s for 14 us a point; -O1
#: took 8.2 s for the same speed, -O0 gave 35 us, casadi's virtual machine 224 us.
FLAGS = ("-Og", "-shared", "-fPIC")


@dataclass
class PointDerivatives:
    """A piece's derivatives at one point: jacobian(z) -> the nonzeros of dF/dz on jacobian_pattern (rows,
    cols); hessian(z, mu) -> those of tril(d2(mu . F)/dz2) on hessian_pattern. casadi Functions, compiled or not."""

    jacobian: Any
    hessian: Any
    jacobian_pattern: tuple[np.ndarray, np.ndarray]
    hessian_pattern: tuple[np.ndarray, np.ndarray]
    points: int  # how many points the piece maps it over

    @classmethod
    def of(cls, piece: Mapped) -> PointDerivatives:
        import casadi as ca

        z = ca.SX.sym("z", piece.index.shape[1])
        value = piece.function(z)
        mu = ca.SX.sym("mu", value.shape[0])
        jacobian = ca.jacobian(value, z)
        hessian = ca.tril(ca.hessian(ca.dot(mu, value), z)[0])
        return cls(ca.Function("point_jacobian", [z], [_nonzeros(jacobian)]), ca.Function("point_hessian", [z, mu], [_nonzeros(hessian)]),
                   _triplets(jacobian), _triplets(hessian), piece.index.shape[0])


def derivatives(transcription: Transcription) -> dict[str, Any]:
    """{"jac_g": (x, p) -> (g, dg/dx), "hess_lag": (x, p, lam_f, lam_g) -> triu(d2(lam_f f + lam_g . g)/dx2)}:
    casadi Functions for `nlpsol`'s options of the same names."""
    import casadi as ca

    x, n, m = transcription.x, transcription.x.shape[0], transcription.g.shape[0]
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", m)
    mapped = [piece for piece in transcription.pieces if isinstance(piece, Mapped)]  # the others are LinearRows
    compiled = iter(compile_functions([PointDerivatives.of(piece) for piece in mapped]))
    jac, hess = _Sum(), _Sum()  # each entry: coefficient x a local value, summed into (row, col)
    row = 0
    for piece in transcription.pieces:
        if not isinstance(piece, Mapped):
            matrix = piece.matrix.tocoo()
            jac.add(ca.DM(matrix.data), row + matrix.row, matrix.col)
            row += piece.size
            continue
        derivative = next(compiled)
        points, outputs = piece.index.shape[0], piece.function.size1_out(0)
        z = gather(x, piece.index)
        jac.add(ca.vec(derivative.jacobian.map(points)(z)), *_jacobian_entries(piece, derivative.jacobian_pattern, row))
        mu = lam_g[row : row + piece.size]
        if piece.selection is not None:
            mu = casadi_sparse(piece.selection.T) @ mu
        hess.add(ca.vec(derivative.hessian.map(points)(z, ca.reshape(mu, outputs, points))), *_hessian_entries(piece, derivative.hessian_pattern))
        row += piece.size
    objective, pattern = _objective_hessian(transcription)
    hess.add(lam_f * objective(x), *pattern)
    p = ca.MX.sym("p", 0)
    return {"jac_g": ca.Function("nlp_jac_g", [x, p], [transcription.g, jac.matrix(m, n)], ["x", "p"], ["g", "jac_g_x"]),
            "hess_lag": ca.Function("nlp_hess_l", [x, p, lam_f, lam_g], [hess.matrix(n, n)], ["x", "p", "lam_f", "lam_g"],
                                    ["triu_hess_gamma_x_x"])}


class _Sum:
    """A sparse matrix whose entries are sums of coefficient x local value, the values casadi column vectors."""

    def __init__(self) -> None:
        self.values: list = []
        self.entries: list = []  # (rows, cols, coefficients, value index)
        self.count = 0

    def add(self, values: Any, rows: np.ndarray, cols: np.ndarray, coefficients: np.ndarray | None = None, local: np.ndarray | None = None) -> None:
        """Entry e is coefficients[e] (default 1) x values[local[e]] (default values[e]) at (rows[e], cols[e])."""
        local = np.arange(len(rows)) if local is None else local
        coefficients = np.ones(len(rows)) if coefficients is None else coefficients
        self.values.append(values)
        self.entries.append((rows, cols, coefficients, self.count + local))
        self.count += values.shape[0]

    def matrix(self, rows: int, cols: int) -> Any:
        import casadi as ca

        row, col, coefficient, local = (np.concatenate(part) for part in zip(*self.entries))
        keys, slot = np.unique(col * rows + row, return_inverse=True)  # column-major: casadi's order
        scatter = coo_matrix((coefficient, (slot, local)), shape=(len(keys), self.count))
        colind = np.searchsorted(keys // rows, np.arange(cols + 1))
        sparsity = ca.Sparsity(rows, cols, colind.tolist(), (keys % rows).tolist())
        return ca.MX(sparsity, casadi_sparse(scatter) @ ca.vertcat(*self.values))


def _nonzeros(matrix: Any) -> Any:
    """A sparse SX matrix's nonzeros as a column (column-major, as `_triplets`)."""
    import casadi as ca

    return ca.vertcat(*matrix.nonzeros()) if matrix.nnz() else ca.SX(0, 1)


def _triplets(matrix: Any) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = matrix.sparsity().get_triplet()
    return np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)


def _jacobian_entries(piece: Mapped, pattern: tuple, row: int) -> tuple:
    """(rows, cols, coefficients, local values) of the piece's Jacobian entries in the NLP's Jacobian."""
    rows, cols = pattern
    points, outputs = piece.index.shape[0], piece.function.size1_out(0)
    point = np.repeat(np.arange(points), len(rows))
    output = point * outputs + np.tile(rows, points)  # the entry's row among the piece's mapped outputs
    col = piece.index[point, np.tile(cols, points)]
    local = np.arange(len(point))
    if piece.selection is None:
        return row + output, col, np.ones(len(point)), local
    selection = piece.selection.tocsc()
    selection.sum_duplicates()
    counts = np.diff(selection.indptr)[output]  # an output feeds the selection's nonzeros in its column
    nonzero = np.repeat(selection.indptr[output], counts) + np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return row + selection.indices[nonzero], np.repeat(col, counts), selection.data[nonzero], np.repeat(local, counts)


def _hessian_entries(piece: Mapped, pattern: tuple) -> tuple:
    """(rows, cols, coefficients) of the piece's Hessian entries in the NLP's upper triangle: a local off-diagonal
    entry counts twice where both of its variables are one."""
    rows, cols = pattern
    points = piece.index.shape[0]
    point = np.repeat(np.arange(points), len(rows))
    i, j = piece.index[point, np.tile(rows, points)], piece.index[point, np.tile(cols, points)]
    return np.minimum(i, j), np.maximum(i, j), np.where((i == j) & np.tile(rows != cols, points), 2.0, 1.0)


def _objective_hessian(transcription: Transcription) -> tuple[Any, tuple]:
    """(x -> nonzeros of triu(d2f/dx2), their (rows, cols)): casadi's, of the expanded objective."""
    import casadi as ca

    x = ca.SX.sym("x", transcription.x.shape[0])
    hessian = ca.triu(ca.hessian(ca.Function("f", [transcription.x], [transcription.f]).expand()(x), x)[0])
    return ca.Function("objective_hessian", [x], [_nonzeros(hessian)]), _triplets(hessian)


def compile_functions(derivatives: list[PointDerivatives]) -> list[PointDerivatives]:
    """The pieces' derivatives, those worth it (`COMPILE_ABOVE`) compiled to C by the system compiler ($CC or
    cc, `FLAGS`; in parallel) into shared libraries cached under $LEGKIT_CACHE (default $XDG_CACHE_HOME/legkit, ~/.cache/legkit) by a
    hash of their functions, so each is compiled once per machine. Without a compiler, or with LEGKIT_COMPILE=0,
    they run on casadi's virtual machine (the same values, slower); so does a piece whose compilation fails (with
    a warning)."""
    import casadi as ca

    compiler = shutil.which(os.environ.get("CC", "cc"))
    if compiler is None or os.environ.get("LEGKIT_COMPILE", "1") == "0":
        return derivatives
    cache = Path(os.environ.get("LEGKIT_CACHE", Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "legkit")) / "casadi"
    jobs: list[tuple[list, Path]] = []
    out: list[tuple[PointDerivatives, tuple | None]] = []  # with (names, library) where compiled
    for derivative in derivatives:
        pair = (derivative.jacobian, derivative.hessian)
        if derivative.points * sum(f.n_instructions() for f in pair) < COMPILE_ABOVE:
            out.append((derivative, None))
            continue
        digest = hashlib.sha256("\n".join([*(f.serialize() for f in pair), *FLAGS, "jacobian hessian"]).encode()).hexdigest()[:20]
        names, library = (f"lk_{digest}_jacobian", f"lk_{digest}_hessian"), cache / f"lk_{digest}.so"
        if not library.exists():
            jobs.append(([ca.Function(name, f.sx_in(), f.call(f.sx_in())) for name, f in zip(names, pair)], library))
        out.append((derivative, (names, library)))
    # The first solve on a machine waits for this (the amble's 20 pieces: 30 s on two cores): say so.
    with ThreadPoolExecutor(os.cpu_count()) as pool, tqdm(total=len(jobs), desc=f"compiling derivatives into {cache}", unit="piece",
                                                          disable=not jobs, leave=False) as bar:
        for _ in pool.map(lambda job: _compile(ca, compiler, *job), jobs):  # the compiler runs outside the GIL
            bar.update()
    return [derivative if built is None or not built[1].exists() else
            replace(derivative, jacobian=ca.external(built[0][0], str(built[1])), hessian=ca.external(built[0][1], str(built[1])))
            for derivative, built in out]


def _compile(ca: Any, compiler: str, functions: list[Any], library: Path) -> None:
    try:
        library.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=library.parent) as directory:
            source = Path(directory) / "pieces.c"
            generator = ca.CodeGenerator(source.name, {"with_header": False})
            for function in functions:
                generator.add(function)
            source.write_text(generator.dump())
            target = Path(directory) / library.name
            subprocess.run([compiler, *FLAGS, str(source), "-o", str(target)], check=True, capture_output=True, text=True)
            os.replace(target, library)  # atomic: a concurrent process sees the whole library or none
    except (OSError, subprocess.CalledProcessError) as error:
        detail = error.stderr.strip()[-500:] if isinstance(error, subprocess.CalledProcessError) else str(error)
        warnings.warn(f"compiling {library.name} failed ({detail}); its piece runs on casadi's virtual machine", RuntimeWarning, stacklevel=2)
