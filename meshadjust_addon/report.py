"""What a step says: the :class:`Report` every step returns, and the
sentences for a failure (:func:`user_cause`), a face count (:func:`about`)
and a fit's change (:func:`fit_change`) (a share of the size: ``core.percent``)."""

from dataclasses import dataclass, field

from .. import core


@dataclass(frozen=True)
class Report:
    """What a step did, for the UI and logs. ``level`` is ``'INFO'`` or
    ``'WARNING'`` (something was not done, or not as asked: see
    ``warnings``)."""

    message: str
    faces_in: int = 0
    faces_out: int = 0
    deviation_pct: float = float("nan")
    seconds: float = 0.0
    level: str = 'INFO'
    warnings: tuple = ()
    cleaning: dict = field(default_factory=dict)   #: ``core.CleanReport.to_dict()`` of a simplify


def user_cause(exc, what, obj_name):
    """A message for a failed step that names the object and the cause the
    user can act on, with the core's evidence after it."""
    text = str(exc)
    if "non-manifold" in text:
        cause = ("the cage has non-manifold vertices or edges (bowties, edges shared by more "
                 "than two faces), which subdivision cannot refine; clean the source "
                 "(Mesh > Clean Up) or simplify it with Keep topology off")
    elif isinstance(exc, core.TopologyMismatchError):
        cause = "the cage's topology no longer matches its binding"
    else:
        cause = text
        text = ""
    return f"{what} '{obj_name}' failed: {cause}" + (f" ({text})" if text else "")


def vertices(n, kind=""):
    """``n`` vertices as a report says it: "1 cage vertex", "3,001 cage
    vertices" (``kind`` "cage"), "0 vertices"."""
    return f"{n:,} " + (f"{kind} " if kind else "") + ("vertex" if n == 1 else "vertices")


def about(n):
    """A face count as a reader says it: 5,120, 252k, 2M or 1.1M."""
    if n >= 999_500:
        return f"{n / 1e6:.1f}".removesuffix(".0") + "M"
    return f"{n / 1000:.0f}k" if n >= 10_000 else f"{n:,}"


def fit_change(fit):
    """A ``core.FitResult``'s mean distance before and after, as shares of
    the size: ``"0.13% -> 0.079%"``."""
    d = fit.mean_distance
    return f"{core.percent(d[0] / fit.diagonal)} -> {core.percent(d[-1] / fit.diagonal)}"
