"""The config and its schema: the config checked against ``schemas/config.schema.yaml`` with the
schema's defaults filled in (:func:`validate_config`), JSON-schema problems as short one-line
messages (:func:`schema_errors`, also used for the take sheet's rows) and the keys that moved
(:data:`RENAMED_KEYS`).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from os import PathLike

from scan2morph.errors import InputError


def load_schema(path: str | PathLike[str]) -> dict:
    """A JSON schema from a YAML (or JSON) file (libyaml's parser where PyYAML has it: the
    same document, about ten times faster than the pure-Python one on the config schema)."""
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    with open(path, encoding="utf-8") as fh:
        return yaml.load(fh, Loader=loader)


def schema_errors(data: object, schema: dict) -> list[tuple[str, str]]:
    """Every way ``data`` breaks ``schema`` (JSON Schema draft 2020-12), as short
    ``(key path, problem)`` pairs, shallowest first. ``key path`` is dotted (``a.b[2].c``),
    ``<top>`` for the whole document; the problem never quotes more than 80 characters of
    the value (jsonschema's own messages can hold a whole schema or config section).
    """
    from jsonschema import Draft202012Validator

    validator = Draft202012Validator(schema)
    errors = sorted(
        validator.iter_errors(data), key=lambda e: (len(e.path), list(map(str, e.path)))
    )
    out = []
    for e in errors:
        path = list(e.absolute_path)
        if e.validator == "additionalProperties" and isinstance(e.instance, dict):
            known = e.schema.get("properties", {})
            extra = [k for k in e.instance if k not in known]
            allowed = ", ".join(sorted(known))
            out += [(_key_path([*path, k]), f"unknown key (known: {allowed})") for k in extra]
        else:
            out.append((_key_path(path), _problem(e)))
    return out


#: The ICP settings of ``align.icp`` (before, keys of ``align`` itself).
_ICP_KEYS = (
    "method",
    "max_correspondence_mm",
    "max_iterations",
    "robust_kernel",
    "kernel_k_mm",
    "kernel_noise_sigmas",
    "trim_rounds",
    "trim_radius_mm",
    "trim_sigma",
    "min_fitness",
    "max_rmse_ratio",
    "max_rmse_mm",
    "min_inlier_fraction",
)
_LIP_KEYS = ("prior", "stretch", "min_contrast", "search", "max_shift", "min_share")
#: Config keys that moved (old dotted path -> new): a config or sweep table still naming one
#: is refused with one line naming the new key.
RENAMED_KEYS = {
    **{f"refine.jaw_{k}": f"refine.jaw.{k}" for k in ("prior", "start", "end", "max_rmse_ratio")},
    **{f"refine.lip_{k}": f"refine.lip.{k}" for k in _LIP_KEYS},
    **{f"refine.lower_lip_{k}": f"refine.lower_lip.{k}" for k in ("prior", "shrink")},
    **{f"align.{k}": f"align.icp.{k}" for k in _ICP_KEYS},
}


def renamed_keys(config: Mapping) -> list[str]:
    """The old keys of :data:`RENAMED_KEYS` that ``config`` still uses, each as
    ``"{old}: renamed to {new}"``."""
    found = []
    for old, new in RENAMED_KEYS.items():
        section, key = old.split(".")
        if isinstance(config.get(section), Mapping) and key in config[section]:
            found.append(f"{old}: renamed to {new}")
    return found


def validate_config(config: dict, schema: str | PathLike[str], source: str = "config") -> dict:
    """Check a config against its schema and fill in the schema's defaults, in place.

    Defaults are set as :func:`snakemake.utils.validate` sets them: while validating, every
    property with a ``default`` missing from its object is set to (a copy of) that default,
    and the default's own properties are then checked and filled in turn. In the same pass an
    integral float where the schema takes only integers (``subjects: 2.0``) becomes an ``int``.

    Raises
    ------
    InputError
        Naming ``source``, the first problem's key path and what is wrong (one line; the number
        of further problems is appended); a key that moved (:data:`RENAMED_KEYS`) is named with
        its new path. NaN is refused, and so is an infinity except where the key's schema has
        ``x-infinite: true`` (:data:`INFINITE`).
    """
    from jsonschema import Draft202012Validator, validators

    moved = renamed_keys(config)
    if moved:
        raise InputError(source, "; ".join(moved))
    schema_doc = load_schema(schema)
    keyword = Draft202012Validator.VALIDATORS

    def set_defaults(validator, props, instance, sub):
        if isinstance(instance, dict):
            for name, subschema in props.items():
                if isinstance(subschema, dict) and "default" in subschema:
                    instance.setdefault(name, copy.deepcopy(subschema["default"]))
                if name in instance:
                    instance[name] = integral_value(instance[name], subschema)
        yield from keyword["properties"](validator, props, instance, sub)

    def items_as_int(validator, items, instance, sub):
        if isinstance(instance, list):
            instance[:] = [integral_value(item, items) for item in instance]
        yield from keyword["items"](validator, items, instance, sub)

    filling = validators.extend(
        Draft202012Validator, {"properties": set_defaults, "items": items_as_int}
    )
    for _ in filling(schema_doc).iter_errors(config):
        pass  # the errors are reported below, from a plain validator on the filled config
    problems = schema_errors(config, schema_doc)
    if (bad := _non_finite(config, schema_doc)) is not None:  # the schema's 'number' takes it
        path, value = bad
        word = "a number" if value != value else "a finite number"
        problems.insert(0, (_key_path(path), f"expected {word}, got {value}"))
    if problems:
        key, problem = problems[0]
        more = f" (and {len(problems) - 1} more problems)" if len(problems) > 1 else ""
        raise InputError(source, f"{key}: {problem}{more}")
    return config


def integral_value(value: object, schema: object) -> object:
    """``value`` as an ``int`` when it is an integral float (``2.0``, as YAML reads it) and
    ``schema`` takes integers but no other numbers; else ``value`` unchanged.

    JSON Schema counts 2.0 as an integer, so it passes ``type: integer``, but the code reading
    the key needs an ``int`` (``range(2.0)`` raises).
    """
    if not (isinstance(value, float) and value.is_integer() and isinstance(schema, dict)):
        return value
    types = schema.get("type", ())
    types = [types] if isinstance(types, str) else list(types)
    return int(value) if "integer" in types and "number" not in types else value


#: The schema's mark of a number for which ``.inf`` means something (no limit).
INFINITE = "x-infinite"


def _non_finite(value: object, schema: object, path: tuple = ()) -> tuple | None:
    """The key path and value of the first number in a config that no comparison handles:
    NaN (a threshold of .nan lets everything through, or nothing) or an infinity where the
    key's schema has no ``x-infinite: true`` (a size of .inf mm); None when there is none."""
    schema = schema if isinstance(schema, dict) else {}
    if isinstance(value, float) and not math.isfinite(value):
        return None if value == value and schema.get(INFINITE) else (path, value)
    if isinstance(value, list):
        pairs = [(k, item, schema.get("items")) for k, item in enumerate(value)]
    elif isinstance(value, dict):
        props, extra = schema.get("properties", {}), schema.get("additionalProperties")
        pairs = [(k, item, props.get(k, extra)) for k, item in value.items()]
    else:
        pairs = []
    for key, item, sub in pairs:
        if (found := _non_finite(item, sub, (*path, key))) is not None:
            return found
    return None


def _key_path(path) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top>"


def _short(value: object, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _problem(error) -> str:
    """A short description of a jsonschema ValidationError."""
    kind, arg, value = error.validator, error.validator_value, error.instance
    if kind == "minLength" and value == "":
        return "empty"
    if kind == "required":
        missing = [k for k in arg if isinstance(value, dict) and k not in value]
        return f"missing key {', '.join(repr(k) for k in missing)}"
    if kind == "type":
        return f"expected {arg if isinstance(arg, str) else ' or '.join(arg)}, got {_short(value)}"
    if kind == "enum":
        return f"expected one of {list(arg)}, got {_short(value)}"
    if kind == "pattern":
        return f"{_short(value)} does not match {arg!r}"
    if kind in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        return f"expected a value {dict(_BOUNDS)[kind]} {arg}, got {_short(value)}"
    if kind in ("minItems", "maxItems", "minLength", "maxLength"):
        return f"{kind} {arg}: got {_short(value)}"
    if kind in ("anyOf", "oneOf") and all(isinstance(branch, dict) for branch in arg):
        return f"expected {' or '.join(_accepts(branch) for branch in arg)}, got {_short(value)}"
    message = error.message
    return message if len(message) <= 160 else message[:157] + "..."


_WORDS = {
    "number": "a number",
    "integer": "an integer",
    "string": "a string",
    "boolean": "true or false",
    "null": "null",
    "array": "a list",
    "object": "a mapping",
}
_BOUNDS = (
    ("minimum", ">="),
    ("exclusiveMinimum", ">"),
    ("maximum", "<="),
    ("exclusiveMaximum", "<"),
)


def _accepts(branch: dict) -> str:
    """What one branch of an ``anyOf`` or ``oneOf`` accepts, in words (``'auto'``, ``a number
    > 0``, ``one of ['a', 'b']``), for a message listing every branch."""
    if "const" in branch:
        return repr(branch["const"])
    if "enum" in branch:
        return f"one of {list(branch['enum'])}"
    types = branch.get("type", ())
    types = [types] if isinstance(types, str) else list(types)
    words = " or ".join(_WORDS.get(t, t) for t in types) or "a value"
    bounds = " and ".join(f"{op} {branch[key]}" for key, op in _BOUNDS if key in branch)
    pattern = f" matching {branch['pattern']!r}" if "pattern" in branch else ""
    return f"{words}{pattern}{' ' + bounds if bounds else ''}"
