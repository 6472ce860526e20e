"""Fuzzing the camera and config readers: whatever they are given, they return a valid result
or raise the one error type that names the file or the key."""

from __future__ import annotations

import json
import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sr3d_cli.config import Config, apply_mapping, build_config, to_dict
from sr3d_cli.errors import ConfigError, InputError
from sr3d_cli.io.camera_files import load_camera

NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6))
VALUES = st.one_of(NUMBERS, st.booleans(), st.none(), st.text(max_size=5),
                   st.lists(NUMBERS, max_size=10), st.lists(st.lists(NUMBERS, max_size=4),
                                                             max_size=4))
CAMERA_KEYS = ["K", "width", "height", "depth_scale", "intrinsic_matrix", "fx", "fy", "ppx",
               "ppy", "cx", "cy", "xres", "yres", "camera_matrix", "image_width",
               "image_height", "k"]
FUZZ = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def _check_camera(path, notes):
    try:
        cam = load_camera(path, 0.001, notes)
    except InputError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc)
        return
    assert np.isfinite(cam.K).all() and cam.K[0, 0] > 0 and cam.K[1, 1] > 0
    assert math.isfinite(cam.depth_scale) and cam.depth_scale > 0


@FUZZ
@given(data=st.dictionaries(st.sampled_from(CAMERA_KEYS), VALUES, max_size=8))
def test_camera_json_of_any_content_is_a_camera_or_an_error_naming_the_file(tmp_path, data):
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(data))  # NaN and Infinity as Python's json writes them
    _check_camera(path, [])


@FUZZ
@given(K=st.lists(NUMBERS, min_size=9, max_size=9), size=st.tuples(NUMBERS, NUMBERS),
       scale=st.one_of(st.none(), NUMBERS))
def test_a_native_camera_with_any_numbers(tmp_path, K, size, scale):
    data = {"K": [K[0:3], K[3:6], K[6:9]], "width": size[0], "height": size[1]}
    if scale is not None:
        data["depth_scale"] = scale
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(data))
    notes: list[str] = []
    _check_camera(path, notes)
    if scale is None and notes:
        assert "no depth_scale; assuming io.depth_scale = 0.001" in notes[0]


SECTIONS = {name: list(to_dict(Config())[name]) for name in to_dict(Config())}


@FUZZ
@given(section=st.sampled_from(sorted(SECTIONS)), data=st.data(), value=VALUES)
def test_any_value_of_any_key_is_taken_or_refused_naming_the_key(section, data, value):
    key = data.draw(st.sampled_from(SECTIONS[section]))
    try:
        cfg = apply_mapping(Config(), {section: {key: value}}, "fuzz.yaml")
    except ConfigError as exc:
        assert f"'{section}.{key}' in fuzz.yaml" in str(exc) and "\n" not in str(exc)
        return
    taken = getattr(getattr(cfg, section), key)
    for x in taken if isinstance(taken, list) else [taken]:
        assert not isinstance(x, float) or math.isfinite(x)


@FUZZ
@given(text=st.text(max_size=60))
def test_any_set_item_is_taken_or_refused(text):
    try:
        build_config(None, [text])
    except ConfigError as exc:
        assert "\n" not in str(exc).strip() or "YAML" in str(exc)


@FUZZ
@given(raw=st.binary(max_size=200))
def test_a_config_file_of_any_bytes_is_taken_or_refused_naming_it(tmp_path, raw):
    path = tmp_path / "c.yaml"
    path.write_bytes(raw)
    try:
        build_config(path)
    except ConfigError as exc:
        assert str(path) in str(exc)
