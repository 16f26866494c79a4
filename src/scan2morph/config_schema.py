"""The config and its schema: the config checked against ``schemas/config.schema.yaml`` with the
schema's defaults filled in (:func:`validate_config`), JSON-schema problems as short one-line
messages (:func:`schema_errors`, also used for the take sheet's rows) and the keys that moved
(:data:`RENAMED_KEYS`).
"""

from __future__ import annotations

import copy
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
    and the default's own properties are then checked and filled in turn.

    Raises
    ------
    InputError
        Naming ``source``, the first problem's key path and what is wrong (one line; the number
        of further problems is appended); a key that moved (:data:`RENAMED_KEYS`) is named with
        its new path.
    """
    from jsonschema import Draft202012Validator, validators

    moved = renamed_keys(config)
    if moved:
        raise InputError(source, "; ".join(moved))
    schema_doc = load_schema(schema)
    properties = Draft202012Validator.VALIDATORS["properties"]

    def set_defaults(validator, props, instance, sub):
        if isinstance(instance, dict):
            for name, subschema in props.items():
                if isinstance(subschema, dict) and "default" in subschema:
                    instance.setdefault(name, copy.deepcopy(subschema["default"]))
        yield from properties(validator, props, instance, sub)

    filling = validators.extend(Draft202012Validator, {"properties": set_defaults})
    for _ in filling(schema_doc).iter_errors(config):
        pass  # the errors are reported below, from a plain validator on the filled config
    problems = schema_errors(config, schema_doc)
    if (nan := _nan_path(config)) is not None:  # the schema's 'number' takes it
        problems.insert(0, (_key_path(nan), "expected a number, got nan"))
    if problems:
        key, problem = problems[0]
        more = f" (and {len(problems) - 1} more problems)" if len(problems) > 1 else ""
        raise InputError(source, f"{key}: {problem}{more}")
    return config


def _nan_path(value: object, path: tuple = ()) -> tuple | None:
    """The key path of the first NaN in a config (a number every comparison refuses: a
    threshold of .nan would let everything through, or nothing), None when there is none."""
    if isinstance(value, float) and value != value:
        return path
    items = value.items() if isinstance(value, dict) else ()
    for key, item in enumerate(value) if isinstance(value, list) else items:
        if (found := _nan_path(item, (*path, key))) is not None:
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
        bound = {"minimum": ">=", "maximum": "<=", "exclusiveMinimum": ">"}.get(kind, "<")
        return f"expected a value {bound} {arg}, got {_short(value)}"
    if kind in ("minItems", "maxItems", "minLength", "maxLength"):
        return f"{kind} {arg}: got {_short(value)}"
    message = error.message
    return message if len(message) <= 160 else message[:157] + "..."
