"""core/pages.py: the core's entry points run with NumPy's huge pages off and
put NumPy's setting back afterwards (nested calls, exceptions, threads);
MESHADJUST_HUGEPAGES=1 leaves NumPy's setting alone."""

import os
import subprocess
import sys
import threading

import numpy as np
import pytest

import core
from core import pages
from tests.mesh_factory import torus

pytestmark = pytest.mark.skipif(
    pages.numpy_hugepages() is None or pages.KEEP_HUGEPAGES,
    reason="NumPy has no huge-page setting here, or MESHADJUST_HUGEPAGES=1")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(params=[True, False], ids=["numpy on", "numpy off"])
def numpy_setting(request):
    """NumPy's setting before the test (both), put back after it."""
    setter = pages._numpy_setter()
    before = setter(request.param)
    yield request.param
    setter(before)


def test_off_inside_and_restored_after(numpy_setting):
    seen = []

    @pages.plain_pages
    def work():
        seen.append(pages.numpy_hugepages())
        return np.ones(10).sum()
    assert work() == 10.0
    assert seen == [False]
    assert pages.numpy_hugepages() is numpy_setting


def test_nested_calls_and_exceptions_restore_the_outer_setting(numpy_setting):
    seen = []

    @pages.plain_pages
    def inner(fail):
        seen.append(pages.numpy_hugepages())
        if fail:
            raise ValueError("inner failed")

    @pages.plain_pages
    def outer():
        inner(False)
        seen.append(pages.numpy_hugepages())     # still off after the inner call
        with pytest.raises(ValueError):
            inner(True)
        seen.append(pages.numpy_hugepages())
        raise KeyError("outer failed")
    with pytest.raises(KeyError):
        outer()
    assert seen == [False] * 4
    assert pages.numpy_hugepages() is numpy_setting


def test_overlapping_threads_restore_once_both_are_done(numpy_setting):
    started, release = threading.Barrier(2), threading.Event()
    seen = []

    @pages.plain_pages
    def work():
        started.wait(timeout=10)
        release.wait(timeout=10)
        seen.append(pages.numpy_hugepages())
    threads = [threading.Thread(target=work) for _ in range(2)]
    for t in threads:
        t.start()
    release.set()
    for t in threads:
        t.join(timeout=10)
    assert seen == [False, False]
    assert pages.numpy_hugepages() is numpy_setting


def test_core_steps_run_with_plain_pages(numpy_setting):
    """Through the progress callbacks of simplify, fit_cage and bind: NumPy's
    setting is off while they work, back after each."""
    V, F = torus(48, 24, bump=0.02)
    seen = {}

    def probe(step):
        def progress(fraction):
            seen.setdefault(step, set()).add(pages.numpy_hugepages())
        return progress
    cage = core.simplify(V, F, target_faces=200, progress=probe("simplify"))
    assert pages.numpy_hugepages() is numpy_setting
    fit = core.fit_cage(V, F, cage.V, cage.F, levels=1, iterations=2, progress=probe("fit"))
    assert pages.numpy_hugepages() is numpy_setting
    core.bind(V, F, fit.V, cage.F, levels=1, progress=probe("bind"))
    assert seen == {"simplify": {False}, "fit": {False}, "bind": {False}}
    assert pages.numpy_hugepages() is numpy_setting


@pytest.mark.parametrize("name", ["clean_mesh", "simplify", "simplify_symmetric", "fit_cage",
                                  "bind", "deform", "refine", "subdivide", "subdivision_operator",
                                  "closest_points", "surface_distance", "sample_surface",
                                  "read_mesh", "write_mesh"])
def test_public_entry_points_are_wrapped(name):
    assert getattr(core, name).__wrapped__ is not None
    assert core.TriangleIndex.__init__.__wrapped__ is not None


def test_keep_hugepages_leaves_numpy_alone():
    code = ("import core; from core import pages; "
            "print(pages.KEEP_HUGEPAGES, hasattr(core.simplify, '__wrapped__'))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         env={**os.environ, "MESHADJUST_HUGEPAGES": "1"}, check=True).stdout
    assert out.split() == ["True", "False"]
