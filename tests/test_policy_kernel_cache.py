"""ALI3-P's tangent kernel is found in the disk cache without being generated (kronlag.numeric.kernel_cache).

The compiled library of a driver is keyed by a hash of its whole source, which contains the tangent
kernel: before, every process generated the kernel (minutes for Cassie's leg) only to find the library
cached.  Now its text is cached under a key known beforehand (the model's own C source, the kernel's
name, the generator's identity); a model of other equations gets another key.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import MODEL_BUILDERS, derived

import kronlag
from kronlag.numeric import codegen, kernel_cache

FOUR_BAR = dict(l1=0.2, l2=0.6, l3=0.5, l4=0.5, m1=1.0, m2=2.0, m3=1.5, I1=0.2 ** 2 / 12, I2=2 * 0.6 ** 2 / 12,
                I3=1.5 * 0.5 ** 2 / 12, g=9.81, tau=0.5)

pytestmark = pytest.mark.skipif(codegen.c_compiler() is None, reason="needs a C compiler")


@pytest.fixture
def generated(monkeypatch, tmp_path):
    """A fresh cache directory, and the names of the kernels whose C text is generated (in order)."""
    monkeypatch.setenv("KRONLAG_CACHE", str(tmp_path / "cache"))
    names: list[str] = []
    original = codegen.c_kernel

    def counting(kernel, first_chunk):
        names.append(kernel.name)
        return original(kernel, first_chunk)

    monkeypatch.setattr(codegen, "c_kernel", counting)
    return names


def _ali3p_run(equations) -> kronlag.Trajectory:
    model = equations.numeric(FOUR_BAR, backend="c")
    q0, qd0 = model.assemble([0.3, 0.8, 1.35], fixed={"q1": 0.3})
    return kronlag.simulate(model, (0.0, 0.2), q0, qd0, method="ali3p", t_eval=np.linspace(0.0, 0.2, 5))


def test_a_warm_cache_does_not_generate_the_tangent_kernel_again(generated):
    equations = derived("four_bar")
    first = _ali3p_run(equations)
    assert generated.count("tangent") == 1
    # a new model of the same equations (as in a second process: nothing of the first one is kept in
    # memory but the cache on disk) finds the kernel's text and the library without generating it
    second = _ali3p_run(equations)
    assert generated.count("tangent") == 1
    assert first.success and second.success
    np.testing.assert_array_equal(first.q, second.q)


def test_other_equations_do_not_hit_a_stale_entry(generated):
    equations = derived("four_bar")
    _ali3p_run(equations)
    system = MODEL_BUILDERS["four_bar"]()  # a new System: the cached equations' stays as it is
    system.add_potential(0.3 * system.coordinates[0] ** 2, name="spring")  # another model, its own tangent
    changed = kronlag.derive(system)
    run = _ali3p_run(changed)
    assert generated.count("tangent") == 2 and run.success
    assert kernel_cache.kernel_key(equations.numeric(FOUR_BAR, backend="c").c_source, "tangent") != \
        kernel_cache.kernel_key(changed.numeric(FOUR_BAR, backend="c").c_source, "tangent")


def test_a_damaged_entry_is_generated_again(generated):
    equations = derived("four_bar")
    model = equations.numeric(FOUR_BAR, backend="c")
    text = model.c_kernels("tangent")
    (entry,) = kernel_cache._private_cache_directory().glob("kernel_tangent_*.c")
    entry.write_text(entry.read_text()[:-40])  # truncated: its hash no longer matches
    again = equations.numeric(FOUR_BAR, backend="c").c_kernels("tangent")
    assert again == text and generated.count("tangent") == 2
    assert entry.read_text().endswith(text)


def test_the_key_follows_the_generator(monkeypatch):
    source = "/* a model */"
    key = kernel_cache.kernel_key(source, "tangent")
    assert kernel_cache.kernel_key(source, "potential_energy") != key
    monkeypatch.setattr(kernel_cache, "generator_identity", lambda: "another generator")
    assert kernel_cache.kernel_key(source, "tangent") != key
