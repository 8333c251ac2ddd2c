"""legkit.optimize.pointwise: the NLP's Jacobian and Hessian of the Lagrangian assembled point by point, against
casadi's derivatives of the whole graph, on random small transcriptions (repeated variables within a point,
selections summing several outputs into one row, linear rows); and the compiled pieces' on-disk cache."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.sparse import csr_matrix

from conftest import examples
from legkit.optimize import pointwise
from legkit.optimize.symbolic import LinearRows, Mapped, Transcription


def piece_function(width: int, outputs: int, seed: int) -> ca.Function:
    """A smooth nonlinear F: R^width -> R^outputs with random coefficients."""
    rng = np.random.default_rng(seed)
    z = ca.SX.sym("z", width)
    a, b = rng.normal(size=(outputs, width)), rng.normal(size=(outputs, width))
    return ca.Function("piece", [z], [ca.sin(ca.DM(a) @ z) * (ca.DM(b) @ z) + ca.DM(rng.normal(size=outputs)) * ca.sumsqr(z)])


def sparse_random(rows: int, cols: int, rng: np.random.Generator) -> csr_matrix:
    """About half the entries nonzero, normal."""
    return csr_matrix(rng.normal(size=(rows, cols)) * (rng.random((rows, cols)) < 0.5))


def random_transcription(seed: int, n: int, pieces: int) -> Transcription:
    rng = np.random.default_rng(seed)
    x = ca.MX.sym("x", n)
    parts: list = []
    for p in range(pieces):
        width, outputs, points = rng.integers(1, 5), rng.integers(1, 4), rng.integers(1, 5)
        index = rng.integers(0, n, size=(points, width))  # variables may repeat within a point and across points
        selection = None
        if rng.random() < 0.5:
            selection = sparse_random(rng.integers(1, 6), points * outputs, rng)
        parts.append(Mapped(piece_function(width, outputs, seed + p), index, selection))
        if rng.random() < 0.5:
            parts.append(LinearRows(sparse_random(2, n, rng).tocsc(), rng.normal(size=2)))
    g = ca.vertcat(*[piece.rows(x) for piece in parts])
    f = ca.sumsqr(ca.sin(x)) * x[0]
    return Transcription(x, f, g, tuple(parts))


@examples(30)
@given(seed=st.integers(0, 2**16), n=st.integers(2, 6), pieces=st.integers(1, 3))
def test_pointwise_derivatives_equal_casadis_of_the_whole_graph(seed, n, pieces):
    # Pieces this small stay on casadi's virtual machine (`COMPILE_ABOVE`): the assembly alone is tested here.
    transcription = random_transcription(seed, n, pieces)
    rng = np.random.default_rng(seed + 1)
    x, lam_f, lam_g = rng.normal(size=n), rng.normal(), rng.normal(size=transcription.g.shape[0])
    derivatives = pointwise.derivatives(transcription)
    g, jacobian = derivatives["jac_g"](x, [])
    x_sym, g_sym = transcription.x, transcription.g
    lagrangian = lam_f * transcription.f + ca.dot(ca.DM(lam_g), g_sym)
    whole = ca.Function("whole", [x_sym], [g_sym, ca.jacobian(g_sym, x_sym), ca.hessian(lagrangian, x_sym)[0]])
    g_ref, jacobian_ref, hessian_ref = (np.asarray(ca.DM(value)) for value in whole(x))
    np.testing.assert_allclose(np.asarray(g), g_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(ca.DM(jacobian)), jacobian_ref, rtol=1e-12, atol=1e-12)
    hessian = np.asarray(ca.DM(derivatives["hess_lag"](x, [], lam_f, lam_g)))
    np.testing.assert_allclose(hessian, np.triu(hessian_ref), rtol=1e-10, atol=1e-10)
    assert np.all(np.tril(hessian, -1) == 0.0)  # IPOPT is given the upper triangle


def test_compiled_pieces_equal_the_virtual_machine_and_are_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("LEGKIT_CACHE", str(tmp_path))
    monkeypatch.setattr(pointwise, "COMPILE_ABOVE", 0)
    piece = Mapped(piece_function(4, 3, 0), np.array([[0, 1, 2, 3], [3, 2, 1, 0]]))
    derivative = pointwise.PointDerivatives.of(piece)
    (compiled,) = pointwise.compile_functions([derivative])
    assert compiled.jacobian.class_name() == "External"
    rng = np.random.default_rng(3)
    for _ in range(3):
        z, mu = rng.normal(size=4), rng.normal(size=3)
        np.testing.assert_allclose(np.asarray(compiled.jacobian(z)), np.asarray(derivative.jacobian(z)), rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(np.asarray(compiled.hessian(z, mu)), np.asarray(derivative.hessian(z, mu)), rtol=1e-14, atol=1e-14)
    libraries = sorted((tmp_path / "casadi").iterdir())
    assert len(libraries) == 1 and libraries[0].suffix == ".so"
    built = libraries[0].stat().st_mtime_ns
    pointwise.compile_functions([pointwise.PointDerivatives.of(piece)])  # the same piece again: loaded, not rebuilt
    assert sorted((tmp_path / "casadi").iterdir()) == libraries and libraries[0].stat().st_mtime_ns == built


def test_a_failing_or_missing_compiler_leaves_the_piece_on_the_virtual_machine(tmp_path, monkeypatch):
    monkeypatch.setenv("LEGKIT_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # exits 1 without building anything
    monkeypatch.setattr(pointwise, "COMPILE_ABOVE", 0)
    derivative = pointwise.PointDerivatives.of(Mapped(piece_function(3, 2, 1), np.array([[0, 1, 2]])))
    with pytest.warns(RuntimeWarning, match="compiling"):
        (kept,) = pointwise.compile_functions([derivative])
    assert kept is derivative
    assert not any((tmp_path / "casadi").glob("*.so"))
    monkeypatch.setenv("CC", "no-such-compiler")  # none on the path: the same pieces, uncompiled, without a warning
    assert pointwise.compile_functions([derivative]) == [derivative]
