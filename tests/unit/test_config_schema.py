"""The config checked against its schema: bad values are one line naming the key path."""

from __future__ import annotations

import pytest

from scan2morph.config_schema import INFINITE, validate_config
from scan2morph.errors import InputError
from tests.support.configs import REPO, config_schema, repo_config

SCHEMA = REPO / "schemas" / "config.schema.yaml"


def _set(config: dict, path: str, value) -> None:
    *sections, key = path.split(".")
    node = config
    for section in sections:
        node = node.setdefault(section, {})
    node[key] = value


def _get(config: dict, path: str):
    for key in path.split("."):
        config = config[key]
    return config


@pytest.mark.parametrize(
    "path, value, expected",
    [
        ("synthetic.subjects", 2.0, 2),
        ("synthetic.seed", 7.0, 7),
        ("synthetic.scanner.width", 320.0, 320),
        ("synthetic.rgbd.sensor.frames", 2.0, 2),
        ("smoothing.iterations", 10.0, 10),
        ("stereo.P1", 8.0, 8),  # type [integer, null]
        ("landmarks.stable_points", [28.0, 37, 40.0], [28, 37, 40]),  # items: integer
        ("synthetic.mesh.subjects", [3.0], [3]),
    ],
)
def test_an_integer_key_given_as_an_integral_float_is_taken_as_an_int(path, value, expected):
    """Before: 2.0 passed the schema's 'integer' (JSON Schema counts it as one) and
    synthetic.subjects: 2.0 stopped the workflow with a traceback (range(2.0))."""
    config = repo_config()
    _set(config, path, value)
    validate_config(config, SCHEMA)
    got = _get(config, path)
    assert got == expected
    assert all(type(v) is int for v in (got if isinstance(got, list) else [got]))


def test_a_float_stays_a_float_where_the_schema_takes_numbers():
    config = repo_config()
    _set(config, "mask.radius_mm", 40)
    _set(config, "smoothing.w", 1.0)
    validate_config(config, SCHEMA)
    assert type(config["smoothing"]["w"]) is float and type(config["mask"]["radius_mm"]) is int


@pytest.mark.parametrize(
    "path, value, match",
    [
        ("synthetic.subjects", 2.5, r"^config: synthetic\.subjects: expected integer, got 2\.5$"),
        ("mask.radius_mm", float("inf"), r"^config: mask\.radius_mm: expected a finite number, got inf$"),
        ("synthetic.scanner.noise_mm", float("inf"), r"^config: synthetic\.scanner\.noise_mm: expected a finite number, got inf$"),
        ("mask.radius_mm", float("-inf"), r"^config: mask\.radius_mm: expected a finite number, got -inf"),
        ("smoothing.max_stretch", float("nan"), r"^config: smoothing\.max_stretch: expected a number, got nan$"),
        ("motion_noise.click_noise_px", "Auto", r"^config: motion_noise\.click_noise_px: expected a number > 0 or 'auto', got 'Auto'$"),
        ("motion_noise.click_noise_px", -1, r"^config: motion_noise\.click_noise_px: expected a number > 0 or 'auto', got -1$"),
    ],
)  # fmt: skip
def test_bad_numbers_are_one_line_naming_the_key(path, value, match):
    """Before: .inf passed every key with only a lower bound (NaN alone was refused), and a
    value matching no branch of an anyOf gave jsonschema's 'is not valid under any of the
    given schemas'."""
    config = repo_config()
    _set(config, path, value)
    with pytest.raises(InputError, match=match) as exc:
        validate_config(config, SCHEMA)
    assert "\n" not in str(exc.value)


def _infinite_keys(node, path=""):
    if not isinstance(node, dict):
        return []
    out = [(path, node)] if node.get(INFINITE) else []
    for key, sub in node.get("properties", {}).items():
        out += _infinite_keys(sub, f"{path}.{key}" if path else key)
    return out


def test_inf_is_taken_where_the_schema_gives_it_a_meaning():
    keys = _infinite_keys(config_schema())
    assert {p for p, _ in keys} == {"refine.shape.texture_gate_px", "smoothing.max_stretch"}
    for path, node in keys:
        assert ".inf" in node["description"], path  # the meaning is documented
        config = repo_config()
        _set(config, path, float("inf"))
        validate_config(config, SCHEMA)
        assert _get(config, path) == float("inf")
