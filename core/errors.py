"""The core's own exceptions.

Every error the core raises on purpose is a :class:`MeshAdjustError`, so a
caller (the Blender operators, the batch CLI) can catch exactly those and turn
them into a report, while real bugs still surface as tracebacks.

Messages name the function, the broken precondition and the evidence, e.g.
``simplify: 7 non-manifold edges, e.g. (12, 40)``.
"""


class MeshAdjustError(Exception):
    """Base class of every error raised on purpose by ``core``."""


class InvalidMeshError(MeshAdjustError, ValueError):
    """The mesh given to a core function breaks one of its preconditions
    (shapes, dtypes, NaN coordinates, indices out of range, non-manifold
    topology where it cannot be handled)."""


class InvalidArgumentError(MeshAdjustError, ValueError):
    """A parameter other than the mesh is out of range or inconsistent
    (an impossible target, an unknown scheme name)."""


class TopologyMismatchError(MeshAdjustError, ValueError):
    """A cage whose topology no longer matches the one a binding was made
    for (vertices added or removed, faces changed)."""


class CancelledError(MeshAdjustError):
    """A long computation was stopped by its ``progress`` callback (which
    returned False); nothing it would have returned exists."""
