"""Deep kinematic chains build fast: symbol checks and rotation products visit shared subexpressions once."""

import importlib.metadata
import warnings
from pathlib import Path

import pytest
import sympy as sp

import kronlag
from kronlag.app.cli import main
from kronlag.core.errors import ModelError
from kronlag.model.rotations import matrix_product
from kronlag.model.symbols import free_symbols


def _shared_chain(depth: int, start: sp.Expr, step: sp.Symbol) -> sp.Expr:
    """An expression whose every level uses the previous one twice: 2**depth paths through ``depth``
    distinct nodes (what the world-frame poses of a deep chain look like)."""
    expression = start
    for _ in range(depth):
        expression = sp.sin(expression) * step + sp.cos(expression)
    return expression


def test_free_symbols_visits_shared_subexpressions_once():
    x, y, z = sp.symbols("x y z")
    deep = _shared_chain(80, x, y)  # SymPy's own free_symbols would walk 2**80 paths
    assert free_symbols(deep) == {x, y}
    assert free_symbols(sp.Matrix([deep, z])) == {x, y, z}


def test_free_symbols_keeps_bound_symbols_out():
    x, y, z = sp.symbols("x y z")
    f = sp.Function("f")
    expression = sp.Integral(x * y, (x, 0, 1)) + sp.Derivative(f(z), z) + sp.Lambda(x, x + y)(z)
    assert free_symbols(expression) == expression.free_symbols == {y, z}


def test_deep_body_is_added_and_unknown_symbols_are_named():
    q, a = sp.symbols("q a")
    p, r = sp.symbols("p r")
    system = kronlag.System([q], parameters=[a])
    deep = _shared_chain(80, q, a)
    system.add_body(kronlag.PointMass("tip", mass=1, position=(deep, 0, 0)))
    with pytest.raises(ModelError, match=r"^body 'bad' position uses a symbol that is neither a coordinate "
                                         r"nor a declared parameter \(add it to parameters=\.\.\.\): p, r$"):
        system.add_body(kronlag.PointMass("bad", mass=1, position=(_shared_chain(80, q, p) + r, 0, 0)))
    with pytest.raises(ModelError, match=r"^constraint 'c' uses a symbol .*: p$"):
        system.add_constraint(_shared_chain(80, q, p), name="c")
    system.add_constraint(deep - 1, name="deep")


def test_matrix_product_agrees_with_sympy():
    q1, q2 = sp.symbols("q1 q2")
    left = sp.Matrix([[sp.cos(q1), -sp.sin(q1), 0], [sp.sin(q1), sp.cos(q1), 0], [0, 0, 1]])
    right = sp.Matrix([[1, 0, 0], [0, sp.cos(q2), -sp.sin(q2)], [0, sp.sin(q2), sp.cos(q2)]])
    for a, b in ((left, right), (right, left), (left, sp.Matrix([q1, 0, q2]))):
        assert sp.simplify(matrix_product(a, b) - a * b) == sp.zeros(a.rows, b.cols)


def test_derive_converts_a_deep_shared_expression():
    q, a = sp.symbols("q a")
    system = kronlag.System([q], parameters=[a])
    system.add_body(kronlag.PointMass("tip", mass=1, position=(_shared_chain(60, q, a), 0, 0)))
    system.add_constraint(_shared_chain(60, q, a) - 1, name="deep")
    equations = kronlag.derive(system)
    x0 = {q: 0.3, a: 0.7}
    depth_value = 0.3
    for _ in range(60):
        depth_value = float(sp.sin(depth_value) * 0.7 + sp.cos(depth_value))
    assert float(equations.Phi[0].subs(x0)) == pytest.approx(depth_value - 1, rel=1e-12)


def _cassie() -> Path:
    try:
        distribution = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    path = Path(str(distribution.locate_file(
        "cmeel.prefix/share/example-robot-data/robots/cassie_description/robots/cassie_v2.sdf")))
    if not path.is_file():
        pytest.skip("example-robot-data has no cassie_v2.sdf")
    return path


@pytest.mark.slow
def test_check_reports_cassie(capsys):
    """``kronlag check cassie_v2.sdf`` (~40 s of CPU: it derives and builds the whole model) reports the
    bodies, the loop-closing rows, the dropped zero row and the mobility 18 against m - r = 17
    (29 coordinates, 12 rows of rank 11: the right foot's out-of-plane row is dependent)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["check", str(_cassie())]) == 0
    out = capsys.readouterr().out
    assert "23 bodies, 29 coordinates, 12 holonomic and 0 nonholonomic constraints" in out
    assert "rows dropped as identically zero (redundant): left-plantar-foot-joint.z" in out
    assert ("loop closed by left-pitch-rod-joint (ball, left-achilles-rod to left-hip-pitch): rows .x .y .z "
            "(components in the frame of left-hip-pitch)") in out
    assert "degrees of freedom = 18" in out and "m - r - s = 17" in out
    assert ("rank of each joint's or loop's rows at the assembled state: root_joint 1 of 1; left-pitch-rod-joint 3 of 3; "
            "right-pitch-rod-joint 3 of 3; right-plantar-foot-joint 2 of 3; left-plantar-foot-joint 2 of 2") in out
    assert "rows dependent on the others at the assembled state (redundant): right-plantar-foot-joint.z" in out
    assert ("loop closed by left-plantar-foot-joint (ball, left-plantar-rod to left-foot): rows .x .y (components in "
            "the frame of left-tarsus), .z dropped (identically zero)") in out
