"""Fit a cage, bind a dense mesh to it, deform and refine: the adjustment API.

This module gathers the public names of the two halves of the adjustment
step, each in its own file:

* :mod:`.fit` -- :func:`fit_cage`: least-squares cage positions whose
  subdivision surface matches the dense surface (undoes QEM shrinkage).
* :mod:`.binding` -- :func:`bind`, :func:`deform`, :func:`refine` and the
  :class:`Binding` they share: the dense mesh as displacements in local frames
  of the subdivided cage.

Typical use::

    cage = simplify(V, F, target_faces=2000)
    fit = fit_cage(V, F, cage.V, cage.F, levels=2, creases=cage.feature_edges)
    b = bind(V, F, fit.V, cage.F, levels=2, creases=cage.feature_edges)
    V_edited = deform(b, V_cage_edited)              # dense topology kept
    V_fine, F_fine = refine(b, V_cage_edited)        # regular topology, detail kept
"""

from .binding import Binding, Frames, RefineResult, bind, deform, frames, refine
from .fit import FitResult, fit_cage

__all__ = ["Binding", "Frames", "RefineResult", "FitResult", "bind", "deform", "refine",
           "frames", "fit_cage"]
