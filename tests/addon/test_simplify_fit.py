"""The add-on's Simplify fits its cage to the source as its simplify cleaned it."""

import sys

import numpy as np

from tests.addon.conftest import MODULE, make_object
from tests.addon.test_operators import bumpy_sphere
from tests.mesh_factory import with_debris


def test_simplify_fits_to_the_source_as_its_simplify_cleaned_it(scene):
    # 30 specks too small for one face of the 40 asked: the simplify drops them (the
    # default cleaning keeps them), and the fit, to the surface the collapse saw, is not
    # pulled by them
    V, F = with_debris(*bumpy_sphere(3), k=30, size=2e-2)
    dense = make_object("dense", V, F)
    api = sys.modules[MODULE + ".meshadjust_addon.api"]
    core = sys.modules[MODULE + ".core"]
    steps = sys.modules[MODULE + ".meshadjust_addon.cage_steps"]
    job = api.prepare_simplify(dense, api.SimplifyParams(target_faces=40, bind=False))
    api.compute_simplify(job)
    res = job.result
    assert res.cleaning.n_debris_components == 30
    assert core.clean_mesh(job.V, job.F).report.n_debris_components == 0
    kw = dict(levels=steps.fit_levels(job.levels), scheme=job.params.scheme,
              creases=res.feature_edges if len(res.feature_edges) else None)
    assert np.array_equal(job.fit.V, core.fit_cage(*res.cleaned, res.V, res.F, clean=False,
                                                   **kw).V)
    # (the core's own fit cleans as a simplify to the cage's face count: the same fit)
    assert np.array_equal(job.fit.V, core.fit_cage(job.V, job.F, res.V, res.F, **kw).V)
    kept = core.clean_mesh(job.V, job.F)
    assert not np.array_equal(job.fit.V, core.fit_cage(kept.V, kept.F, res.V, res.F,
                                                       clean=False, **kw).V)


def test_fit_after_a_simplify_fits_as_the_simplify_s_own_fit(scene):
    # Simplify without the fit, then Fit: the specks too small for one face of the cage
    # are left out as the Simplify's own fit leaves them out (the same fit but for the
    # float32 rounding of the cage it starts from); a cleaning without the face budget
    # keeps them
    V, F = with_debris(*bumpy_sphere(3), k=30, size=2e-2)
    api = sys.modules[MODULE + ".meshadjust_addon.api"]
    core = sys.modules[MODULE + ".core"]
    steps = sys.modules[MODULE + ".meshadjust_addon.cage_steps"]
    fitted = api.prepare_simplify(make_object("dense", V, F),
                                  api.SimplifyParams(target_faces=40, bind=False))
    api.compute_simplify(fitted)
    source = make_object("plain", V, F)
    plain = api.prepare_simplify(source, api.SimplifyParams(target_faces=40, bind=False,
                                                            fit=False))
    cage, _ = api.commit_simplify(source, api.compute_simplify(plain))
    job = api.compute_fit(api.prepare_fit(cage))
    res = plain.result
    assert np.array_equal(res.V, fitted.result.V) and res.F.shape[0] == 40
    apart = np.abs(job.fit.V - fitted.fit.V).max()
    assert apart < 1e-5 * core.bbox_diagonal(V)
    kept = core.clean_mesh(plain.V, plain.F)
    specks = core.fit_cage(kept.V, kept.F, res.V, res.F, levels=steps.fit_levels(job.levels),
                           scheme=job.scheme, creases=job.creases, clean=False)
    assert np.abs(specks.V - fitted.fit.V).max() > 100 * apart
