"""Scenes validate every field, close effect dependencies, and fail with one line naming the field."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diathermy.errors import SceneError
from diathermy.scene import (
    EFFECTS,
    Scene,
    builtin_scene,
    builtin_scene_names,
    close_effects,
    load_scene,
    scene_from_dict,
    scene_json_schema,
)


def test_builtin_scenes_are_valid_and_round_trip(tmp_path):
    assert {
        "default",
        "fixed-electrode",
        "moving-electrode",
        "moving-electrode-slow",
        "coagulation",
    } <= set(builtin_scene_names())
    for name in builtin_scene_names():
        scene = builtin_scene(name)
        path = tmp_path / f"{name}.json"
        path.write_text(scene.model_dump_json())
        assert load_scene(path) == scene


def test_yaml_scene(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("name: y\ngrid: [5, 5, 9]\neffects: [thermal]\nsteps: 3\n")
    s = load_scene(path)
    assert s.grid == (5, 5, 9) and s.closed_effects == ("thermal",)


@pytest.mark.parametrize(
    ("effects", "closed"),
    [
        (["dissection"], ("thermal", "vaporization", "mechanics", "dissection")),
        (["desiccation"], ("electric", "thermal", "vaporization", "desiccation")),
        (["thermal_damage", "electric"], ("electric", "thermal", "thermal_damage")),
        (["electric"], ("electric",)),
    ],
)
def test_effect_closure(effects, closed):
    assert close_effects(effects) == closed


@given(st.lists(st.sampled_from(EFFECTS), max_size=7))
def test_closure_is_idempotent_and_ordered(effects):
    closed = close_effects(effects)
    assert close_effects(closed) == closed
    assert list(closed) == sorted(closed, key=EFFECTS.index)
    assert set(effects) <= set(closed)


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"grid": [2, 3, 3]}, "grid"),
        ({"dt_s": -1}, "dt_s"),
        ({"dt_s": "nan"}, "dt_s"),
        ({"material": {"poisson_ratio": 0.7}}, "poisson_ratio"),
        ({"material": {"bogus": 1}}, "material.bogus"),
        ({"electrodes": [{"position_m": [1.0, 1.0]}]}, "electrodes.0"),
        ({"electrodes": [{"radius_m": 0}]}, "electrodes.0.radius_m"),
        ({"electrodes": [{"schedule_s": [[2, 1]]}]}, "electrodes.0.schedule_s"),
        ({"effects": ["bogus"]}, "effects.0"),
        ({"electrodes": [], "effects": ["electric"]}, "electric"),
        ({"electrodes": [{"name": "a"}, {"name": "a"}]}, "unique"),
        ({"schema_version": 2}, "schema_version"),
        ({"unknown_field": 1}, "unknown_field"),
        ({"level_set": {"removal": "half"}}, "level_set.removal"),
    ],
)
def test_bad_scene_names_the_field(data, field):
    with pytest.raises(SceneError) as exc:
        scene_from_dict(data)
    msg = str(exc.value)
    assert field in msg and "\n" not in msg


def test_bad_files(tmp_path):
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(SceneError, match="not valid json"):
        load_scene(bad)
    bad.write_text("[1, 2]")
    with pytest.raises(SceneError, match="mapping"):
        load_scene(bad)
    binary = tmp_path / "bin.json"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(SceneError, match="UTF-8"):
        load_scene(binary)


def test_schema_is_json_and_describes_scene():
    schema = scene_json_schema()
    json.dumps(schema)
    assert {"grid", "electrodes", "effects", "material"} <= set(schema["properties"])


@settings(max_examples=50)
@given(
    st.dictionaries(
        st.sampled_from(["grid", "dt_s", "steps", "effects", "block_m"]),
        st.one_of(
            st.none(),
            st.integers(-5, 5),
            st.floats(allow_nan=True),
            st.text(max_size=5),
            st.lists(st.integers(-2, 40), max_size=4),
        ),
    )
)
def test_arbitrary_input_never_crashes(data):
    """Whatever comes in, the result is a Scene or a SceneError — never another exception."""
    try:
        assert isinstance(scene_from_dict(data), Scene)
    except SceneError:
        pass


def test_published_scene_schema_is_fresh():
    """openapi/scene.schema.json is what `diathermy schema --out openapi/scene.schema.json` writes."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "openapi" / "scene.schema.json"
    assert json.loads(path.read_text()) == scene_json_schema(), "regenerate with diathermy schema"


@pytest.mark.parametrize(
    ("mechanics", "field"),
    [
        ({"correction": "global"}, "mechanics.correction"),
        ({"patch_threshold": 0}, "mechanics.patch_threshold"),
        ({"patch_threshold": 1.5}, "mechanics.patch_threshold"),
        ({"patch_layers": -1}, "mechanics.patch_layers"),
        ({"patch_layers": 9}, "mechanics.patch_layers"),
    ],
)
def test_bad_patch_settings_name_their_field(mechanics, field):
    with pytest.raises(SceneError, match=field):
        scene_from_dict({"mechanics": {"backend": "cnn", **mechanics}})
    assert scene_from_dict({"mechanics": {"backend": "cnn"}}).mechanics.correction == "patch"
