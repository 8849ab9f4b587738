"""Every MeshAdjust setting, declared once.

:data:`SETTINGS` is the table: each entry a :class:`Setting` with its label,
tooltip, default and limits. Everything else is derived from it:

* the operators' redo-panel properties and the scene settings the N-panel
  shows, through annotated mixins (:func:`mixin`), the way Blender's own
  add-ons share properties between a ``PropertyGroup`` and an operator;
* the add-on preferences (:data:`PREFERENCES`), which seed every scene's
  settings (:data:`SEEDED`) without a button;
* the defaults of the context-free API (``api.SimplifyParams``), through
  :func:`default`;
* the panel's copy of the scene settings onto an operator button
  (:func:`copy_to_operator`).

An operator property may carry another name than its setting (``refine``'s
``scheme`` is the setting ``refine_scheme``, which has an "As bound" choice):
the groups below map property names to setting keys. A test walks the RNA of
every operator, the scene settings and the preferences against this table.
"""

import numbers
from dataclasses import dataclass, field

from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

SCHEMES = [
    ('loop', "Loop", "Loop (1987): approximating and smooth, the default: over 54 measured "
                     "edits it folded no face where the edit left the cage unfolded "
                     "(butterfly 2), and 304 in all (butterfly 696)"),
    ('butterfly', "Butterfly", "Modified butterfly (Zorin et al. 1996): interpolating, the cage "
                               "vertices stay on the surface; tighter on bends, but an edit can "
                               "fold the surface"),
]
TARGET_MODES = [
    ('FACES', "Faces", "Stop at a face count"),
    ('RATIO', "Ratio", "Stop at a fraction of the input's faces"),
    ('ERROR', "Max error", "Stop before any collapse whose error exceeds a percentage of the "
                           "mesh size (bounding-box diagonal)"),
]
OUTPUTS = [
    ('EDITED', "Edited original", "A copy of the source deformed by the cage edit: same "
                                  "topology, UVs and attributes kept"),
    ('SHAPE_KEY', "Shape key", "The edit as a shape key of the source itself, named after the "
                               "cage (value 1.0; the Basis is not touched)"),
    ('REFINED', "Refined mesh", "The subdivided edited cage with the source's detail added"),
    ('BOTH', "Edited and refined", "Update the edited original and the refined mesh"),
]
AS_BOUND = [('BOUND', "As bound", "The scheme the cage is bound with")]
AXES = [(a, a, f"Mirror across the object's local {a} = 0 plane") for a in "XYZ"]

_MAKERS = {'BOOL': BoolProperty, 'INT': IntProperty, 'FLOAT': FloatProperty,
           'ENUM': EnumProperty, 'STRING': StringProperty}


@dataclass(frozen=True)
class Setting:
    """One setting: its Blender property kind, label, tooltip, default and
    the keyword arguments of the ``bpy.props`` function (limits, subtype,
    enum items)."""

    kind: str
    label: str
    description: str
    default: object
    options: dict = field(default_factory=dict)

    def prop(self):
        """The deferred ``bpy.props`` definition for a class annotation."""
        return _MAKERS[self.kind](name=self.label, description=self.description,
                                  default=self.default, **self.options)


SETTINGS = {
    # --- simplify
    "target_mode": Setting('ENUM', "Target", "How the size of the cage is chosen: a face count, "
                           "a fraction of the source's faces or a largest allowed deviation",
                           'FACES', {"items": TARGET_MODES}),
    "target_faces": Setting('INT', "Faces", "Number of triangles of the cage", 2000,
                            {"min": 4, "soft_max": 50000}),
    "ratio": Setting('FLOAT', "Ratio", "Cage faces as a fraction of the source's", 0.02,
                     {"min": 1e-5, "max": 1.0, "subtype": 'FACTOR'}),
    "max_error_pct": Setting('FLOAT', "Max error %", "Largest allowed deviation of a collapse, % "
                             "of the bounding-box diagonal", 0.5, {"min": 0.0, "soft_max": 5.0}),
    "preserve_boundary": Setting('BOOL', "Preserve boundary", "Keep the shape of open borders "
                                 "(heavy constraint planes along them)", True),
    "preserve_topology": Setting('BOOL', "Keep topology", "Keep genus, holes and components. "
                                 "Off: once nothing else can collapse, holes of three edges close "
                                 "and tiny pieces that cannot shrink go", True),
    "close_pinholes": Setting('BOOL', "Close pinholes", "When holes keep the cage from its target, "
                              "cap those smaller than one cage face (a scan's dropouts) and "
                              "simplify again; the report counts them", True),
    "feature_angle_deg": Setting('FLOAT', "Feature angle", "Edges sharper than this (degrees) "
                                 "are kept as creases (180 turns it off)", 60.0,
                                 {"min": 1.0, "max": 180.0}),
    "max_dihedral_deg": Setting('FLOAT', "Max bend", "Stop before a collapse would bend two "
                                "adjacent cage faces by more than this (degrees) away from the "
                                "creases: a rounder cage with more faces (180 turns it off)", 180.0,
                                {"min": 1.0, "max": 180.0}),
    "use_symmetry": Setting('BOOL', "Symmetry", "Make the cage mirror-symmetric about the "
                            "object's local plane (as Decimate's Symmetry), so X-mirror editing "
                            "moves both sides; the fit and the detail absorb the scan's own "
                            "asymmetry", False),
    "symmetry_axis": Setting('ENUM', "Axis", "Axis normal to the mirror plane, which passes "
                             "through the object's origin", 'X', {"items": AXES}),
    "weight_group": Setting('STRING', "Importance group", "Vertex group whose weights make "
                            "areas more important (weight 1: ten times)", ""),
    "lock_group": Setting('STRING', "Locked group", "Vertex group of vertices that must not "
                          "move (weight above 0.5)", ""),
    "fit": Setting('BOOL', "Fit cage", "Move the cage so its subdivision matches the source "
                   "(undoes the shrinkage of simplification)", True),
    "bind": Setting('BOOL', "Bind source", "Bind a copy of the source to the cage so cage edits "
                    "deform it", True),
    "hide_source": Setting('BOOL', "Hide source", "Hide the source object once its cage is made "
                           "(the source itself is never modified)", False),
    # --- binding
    "levels": Setting('INT', "Levels", "Subdivision levels, each multiplying the faces by 4. "
                      "0 (Auto): Bind keeps the cage's current levels, a new cage is bound at "
                      "those that bring the refined mesh closest to the source's face count, at "
                      "most 2 (fast binds and live edits), and Refine makes the refined mesh at "
                      "the closest ones. Other levels: the edit and the refined mesh at those", 0,
                      {"min": 0, "max": 5}),
    "scheme": Setting('ENUM', "Scheme", "Subdivision scheme of the binding", 'loop',
                      {"items": SCHEMES}),
    "refine_scheme": Setting('ENUM', "Scheme", "Subdivision scheme; another one than the cage's "
                             "re-binds from the rest shape, keeping the edit", 'BOUND',
                             {"items": AS_BOUND + SCHEMES}),
    "rebind": Setting('BOOL', "Re-bind", "Bind the source again to the fitted cage (the edit is "
                      "carried over onto the fitted rest shape)", True),
    "keep_edit": Setting('BOOL', "Keep edit", "Bind the cage's rest shape and keep the edit on "
                         "top of it. Off: the cage's current shape becomes the new rest shape "
                         "(the edited original goes back to the source)", True),
    # --- refine
    "output": Setting('ENUM', "Output", "What Refine (and Live) updates", 'EDITED',
                      {"items": OUTPUTS}),
    # --- subdivide any mesh
    "subdivide_levels": Setting('INT', "Levels", "Subdivision levels (each multiplies the faces "
                                "by 4)", 1, {"min": 1, "max": 5}),
    "subdivide_scheme": Setting('ENUM', "Scheme", "Subdivision scheme", 'butterfly',
                                {"items": SCHEMES}),
    "in_place": Setting('BOOL', "In place", "Replace the object's mesh instead of adding a new "
                        "object", False),
    # --- preferences only
    "live_interval": Setting('FLOAT', "Live update interval (s)", "Minimum time between live "
                             "refines while editing", 0.15, {"min": 0.02, "max": 2.0}),
}


def _same(*keys):
    return {k: k for k in keys}


#: operator property name -> setting key, per operator
SIMPLIFY = _same("target_mode", "target_faces", "ratio", "max_error_pct", "preserve_boundary",
                 "preserve_topology", "close_pinholes", "feature_angle_deg", "max_dihedral_deg",
                 "use_symmetry", "symmetry_axis", "weight_group", "lock_group", "fit", "bind",
                 "levels", "scheme", "hide_source")
FIT = _same("rebind")
BIND = {"levels": "levels", "scheme": "refine_scheme", "keep_edit": "keep_edit"}
REFINE = {"output": "output", "levels": "levels", "scheme": "refine_scheme"}
SUBDIVIDE = {"levels": "subdivide_levels", "scheme": "subdivide_scheme", "in_place": "in_place"}
OPERATORS = {"meshadjust.simplify": SIMPLIFY, "meshadjust.fit_cage": FIT,
             "meshadjust.bind": BIND, "meshadjust.refine": REFINE,
             "meshadjust.subdivide": SUBDIVIDE}

#: the scene settings the panel shows (attribute name == setting key)
SCENE = _same(*SIMPLIFY, "refine_scheme", "output", "subdivide_levels", "subdivide_scheme")
#: the add-on preferences, and those of them copied into every scene's settings
PREFERENCES = _same("target_mode", "target_faces", "ratio", "max_error_pct", "preserve_boundary",
                    "preserve_topology", "close_pinholes", "feature_angle_deg", "max_dihedral_deg",
                    "fit", "bind", "hide_source", "levels", "scheme", "output", "subdivide_levels",
                    "subdivide_scheme", "live_interval")
SEEDED = tuple(k for k in PREFERENCES if k in SCENE)


def default(key):
    """The default of setting ``key`` (what the API uses too)."""
    return SETTINGS[key].default


def checked(key, value, where):
    """``value`` for the setting ``key`` as the API takes it: an integer
    within an INT setting's limits, one of an ENUM setting's items, else
    ``core.InvalidArgumentError`` naming ``where``, the setting and what it
    takes (the UI's own limits: the API bypassed them, and ``levels=9`` ran
    two minutes into a 13M-vertex binding, ``levels=2.5`` failed in the
    commit after all the work)."""
    from .. import core
    s = SETTINGS[key]
    if s.kind == 'INT':
        lo, hi = s.options.get("min"), s.options.get("max")
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool) and \
            (lo is None or value >= lo) and (hi is None or value <= hi)
        takes = f"an integer from {lo} to {hi}" if hi is not None else f"an integer >= {lo}"
    elif s.kind == 'ENUM':
        items = [item[0] for item in s.options["items"]]
        ok = isinstance(value, str) and value in items
        takes = "one of " + ", ".join(repr(i) for i in items)
    else:
        return value
    if not ok:
        raise core.InvalidArgumentError(f"{where}: {key} must be {takes}, got {value!r}")
    return int(value) if s.kind == 'INT' else value


def mixin(name, group):
    """A class whose annotations declare the properties of ``group``
    (property name -> setting key), to be mixed into an operator, a
    ``PropertyGroup`` or ``AddonPreferences``."""
    return type(name, (), {"__annotations__": {attr: SETTINGS[key].prop()
                                               for attr, key in group.items()}})


def copy_to_operator(settings, op_props, group):
    """Copy the scene settings onto an operator button's properties: every
    property of ``group`` whose setting the scene has."""
    for attr, key in group.items():
        if key in SCENE:
            setattr(op_props, attr, getattr(settings, key))


def seed(settings, prefs):
    """Copy the preferences' values into a scene's settings."""
    for key in SEEDED:
        setattr(settings, key, getattr(prefs, key))
