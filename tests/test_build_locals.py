"""Building in seconds (issue 19.2): in the large kernels of ``linear_cse`` a temporary used only in the C
function that computes it is a local variable (no workspace entry, no points-to analysis needed to tell
its loads from the stores), and the kernel still computes what its expressions say."""

import re

import numpy as np
import pytest

import kronlag
from kronlag import codegen, models
from kronlag.core import kernels
from kronlag.numeric.codegen import build, c_backend


@pytest.fixture
def chain():
    n = 5
    eom = kronlag.derive(models.closed_chain(n, "absolute"))
    values = {p.name: 1.0 for p in eom.parameters}
    values.update(xg=0.6 * n, yg=0.0)
    return eom, values


def test_large_kernels_keep_temporaries_used_in_one_function_local(chain, monkeypatch):
    eom, _ = chain
    source = codegen.KernelSource(eom)
    monkeypatch.setattr(kernels, "LINEAR_CSE_OUTPUTS", 0)  # this small kernel printed as a large one
    monkeypatch.setattr(c_backend, "C_LOCAL_CHUNK", 400)  # in many functions: some temporaries cross them
    kernel = source.kernel("dynamics")
    text, chunks = codegen.c_kernel(kernel, 1)
    assert chunks > 3
    local = set(re.findall(r"const double (x\d+) = ", text))
    shared = set(map(int, re.findall(r"\bw\[(\d+)\] = ", text)))
    assert local and shared and len(local) + len(shared) == len(kernel.temporaries)
    assert shared == set(range(len(shared)))  # the workspace numbered densely
    assert f"double w[{len(shared) + 1}];" in text
    bodies = re.findall(r"void kronlag_dynamics_\d+\([^)]*\)\n\{\n(.*?)\n\}", text, re.DOTALL)
    for body in bodies:  # a local is used only in the function that defines it
        used = set(re.findall(r"\bx\d+\b", body))
        assert used <= set(re.findall(r"const double (x\d+) = ", body))
    # the compilers skip the points-to analysis for such kernels only
    assert "-fno-tree-pta" in build._build_plan(text, 3)[1][1]
    monkeypatch.undo()
    small = codegen.c_kernel(source.kernel("dynamics"), 1)[0]
    assert not re.search(r"const double x\d+ = ", small) and "-fno-tree-pta" not in build._build_plan(small, 3)[1][1]


def test_a_kernel_with_local_temporaries_computes_the_accelerations(chain, tmp_path, monkeypatch):
    if codegen.c_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path))
    eom, values = chain
    reference = eom.numeric(values, backend="python")
    monkeypatch.setattr(kernels, "LINEAR_CSE_OUTPUTS", 0)
    monkeypatch.setattr(c_backend, "C_LOCAL_CHUNK", 400)
    model = eom.numeric(values, backend="c")
    assert re.search(r"const double x\d+ = ", model.c_source)
    rng = np.random.default_rng(7)
    q0, _ = reference.assemble(np.linspace(0.8, -0.8, 5))
    for _ in range(3):
        q, qd = q0 + rng.normal(0, 0.05, 5), rng.normal(0, 1, 5)
        expected = reference.forward_dynamics(q, qd).qdd
        np.testing.assert_allclose(model.forward_dynamics(q, qd).qdd, expected, rtol=1e-12,
                                   atol=1e-12 * np.max(np.abs(expected)))
        np.testing.assert_allclose(model.M(q), reference.M(q), rtol=1e-13, atol=1e-13)
