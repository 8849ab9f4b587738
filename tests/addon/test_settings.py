"""One declaration per setting: every operator property, scene setting and
preference has a tooltip, and every default agrees with ``settings.SETTINGS``
(and with the API's defaults)."""

import dataclasses
import sys

import bpy
import pytest

from tests.addon.conftest import MODULE


def mod(name):
    return sys.modules[MODULE + ".meshadjust_addon." + name]


def _props(rna):
    """The properties a class declares (not those of Blender's base types)."""
    builtin = {"rna_type"} | {p.identifier for base in (bpy.types.AddonPreferences,
                                                        bpy.types.PropertyGroup)
                              for p in base.bl_rna.properties}
    return [p for p in rna.properties if p.identifier not in builtin]


def _default(prop):
    if prop.type == 'ENUM':
        return prop.default_flag if prop.is_enum_flag else prop.default
    if getattr(prop, "array_length", 0):
        return tuple(prop.default_array)
    return prop.default


def _check(where, rna, group):
    """Problems of ``rna``'s properties against the table: (where, name, what)."""
    table = mod("settings").SETTINGS
    problems = []
    for prop in _props(rna):
        if not prop.description.strip():
            problems.append((where, prop.identifier, "no description"))
        if prop.type == 'ENUM':
            for item in prop.enum_items:
                if not item.description.strip():
                    problems.append((where, f"{prop.identifier}.{item.identifier}",
                                     "enum item without description"))
        key = group.get(prop.identifier)
        if key is None:
            continue
        want = table[key].default
        got = _default(prop)
        same = got == pytest.approx(want, rel=1e-6) if prop.type == 'FLOAT' else got == want
        if not same:
            problems.append((where, prop.identifier, f"default {got!r}, the table says {want!r}"))
        if prop.description != table[key].description:
            problems.append((where, prop.identifier, "description differs from the table"))
    return problems


def test_every_operator_property_has_a_tooltip_and_the_tables_default(addon):
    settings = mod("settings")
    operators = mod("operators")
    names = [c.bl_idname for c in operators.CLASSES]
    assert all(c.__name__.startswith("MESHADJUST_OT_") for c in operators.CLASSES)
    assert set(settings.OPERATORS) <= set(names)
    problems = []
    for idname in names:
        op = getattr(bpy.ops.meshadjust, idname.split(".")[1])
        rna = op.get_rna_type()
        group = settings.OPERATORS.get(idname, {})
        assert set(group) <= {p.identifier for p in _props(rna)}, idname
        problems += _check(idname, rna, group)
        assert rna.description.strip(), f"{idname} has no tooltip"
    assert problems == []


def test_scene_settings_preferences_and_state_have_tooltips_and_agree(addon):
    settings = mod("settings")
    props = mod("properties")
    problems = _check("scene", props.MeshAdjustSettings.bl_rna, settings.SCENE)
    problems += _check("preferences", props.MeshAdjustPreferences.bl_rna, settings.PREFERENCES)
    problems += _check("object state", props.MeshAdjustObjectState.bl_rna, {})
    assert problems == []
    scene_names = {p.identifier for p in _props(props.MeshAdjustSettings.bl_rna)}
    pref_names = {p.identifier for p in _props(props.MeshAdjustPreferences.bl_rna)}
    assert set(settings.SCENE) <= scene_names and set(settings.PREFERENCES) <= pref_names
    assert set(settings.SEEDED) == set(settings.PREFERENCES) & set(settings.SCENE)


def test_api_defaults_are_the_tables(addon):
    settings = mod("settings")
    api = mod("api")
    for f in dataclasses.fields(api.SimplifyParams):
        if f.name in settings.SETTINGS and f.name not in ("target_faces", "ratio",
                                                          "max_error_pct"):
            assert f.default == settings.default(f.name), f.name
    # no target given: the table's face count
    assert settings.default("hide_source") is False
    assert api.bind_object.__kwdefaults__["keep_edit"] is None   # None: the table's keep_edit


def test_the_operator_and_the_scene_build_the_same_parameters(scene):
    api = mod("api")
    s = bpy.context.scene.meshadjust
    s.target_mode = 'RATIO'
    s.ratio = 0.25
    s.feature_angle_deg = 180.0
    p = api.SimplifyParams.from_settings(s)
    assert (p.target_faces, p.ratio, p.max_error_pct) == (None, pytest.approx(0.25), None)
    assert p.feature_angle_deg == 180.0 and p.levels == 0 and p.hide_source is False
    assert set(p.keywords()) == {f.name for f in dataclasses.fields(api.SimplifyParams)}


class _Recorder:
    def __init__(self):
        object.__setattr__(self, "set", {})

    def __setattr__(self, key, value):
        self.set[key] = value


def test_panel_copies_every_scene_setting_an_operator_has(scene):
    settings = mod("settings")
    panel = mod("panel")
    s = bpy.context.scene.meshadjust
    for idname, group in settings.OPERATORS.items():
        rec = _Recorder()
        settings.copy_to_operator(s, rec, group)
        assert set(rec.set) == {a for a, k in group.items() if k in settings.SCENE}, idname
        for attr, value in rec.set.items():
            assert value == getattr(s, group[attr])
    for mode, field in (('FACES', "target_faces"), ('RATIO', "ratio"), ('ERROR', "max_error_pct")):
        s.target_mode = mode
        fields = panel.simplify_fields(s)
        assert fields[0] == field and all(f in settings.SCENE for f in fields)


def test_sub_panels_one_per_step(addon):
    panel = mod("panel")
    children = [c for c in panel.CLASSES if getattr(c, "bl_parent_id", "")]
    assert {c.bl_parent_id for c in children} == {"MESHADJUST_PT_main"}
    assert [c.bl_label for c in children][:3] == ["1. Simplify", "2. Edit Cage", "3. Refine"]
    for c in panel.CLASSES:
        assert getattr(bpy.types, c.bl_idname, None) is not None, f"{c.bl_idname} not registered"


def test_auto_levels_bring_the_refined_mesh_closest_to_the_source(addon):
    api = mod("api")
    assert api.auto_levels(1500, 251_904) == 4       # 384,000 faces, about the source's 252k
    assert api.auto_levels(300, 5120) == 2
    assert api.auto_levels(2000, 2000) == 1          # at least one level
    assert api.auto_levels(10, 10**9) == api.MAX_AUTO_LEVELS
    for cage, source in ((700, 100_000), (1234, 56_789), (4, 999)):
        L = api.auto_levels(cage, source)
        errs = [abs(cage * 4 ** k - source) for k in range(1, api.MAX_AUTO_LEVELS + 1)]
        assert errs[L - 1] == min(errs)
    steps = mod("cage_steps")
    assert [steps.fit_levels(k) for k in (1, 2, 4)] == [1, 2, steps.core.MAX_FIT_LEVELS]
