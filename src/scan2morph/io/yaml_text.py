"""YAML documents read for their values, refusing a key given twice, with readable errors."""

from __future__ import annotations

from os import PathLike
from pathlib import Path


def load_yaml(text: str):
    """YAML ``text`` as Python objects, by PyYAML's safe loader, refusing a key given twice in
    a mapping (the safe loader keeps the last value silently: a pasted second calibration).

    Parameters
    ----------
    text : str
        The document.

    Returns
    -------
    object
        The document's value (a dict for a mapping).

    Raises
    ------
    yaml.YAMLError
        Not YAML, or a key given twice (a ``ConstructorError`` naming the key and both lines).
    """
    import yaml  # on use: the readers' modules import light

    class UniqueKeyLoader(yaml.SafeLoader):
        pass

    def mapping(loader, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # "<<: *anchor": merged, not repeated
                continue
            key = loader.construct_object(key_node, deep=deep)
            line = key_node.start_mark.line + 1
            if isinstance(key, (str, int, float)) and key in seen:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f"key {key!r} given twice (first on line {seen[key]}): keep one value",
                    key_node.start_mark,
                )
            seen[key] = line
        return loader.construct_mapping(node, deep)

    UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    return yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 (a SafeLoader)


def yaml_problem(exc: Exception) -> str:
    """PyYAML's problem and its line, for a message (its own message's first line is only its
    context: 'while scanning for the next token').

    Parameters
    ----------
    exc : Exception
        What the loader raised.

    Returns
    -------
    str
        ``line N: problem``, or the message's first line when the error has no position.
    """
    problem, mark = getattr(exc, "problem", None), getattr(exc, "problem_mark", None)
    if problem is None or mark is None:
        return str(exc).splitlines()[0]
    problem = problem.replace("character '\\t'", "a tab (YAML indents with spaces)")
    return f"line {mark.line + 1}: {problem}"


def config_file_problem(path: str | PathLike[str]) -> str | None:
    """Why a config file cannot be read as one (one line naming it), or None.

    What Snakemake's own reading lets through or says without the file and the line: a file
    that is missing or a folder, not YAML (with the line), a key or section given twice
    (Snakemake keeps the last silently), not a mapping of config sections. ``tools/
    check_config.py`` (``make run CONFIG=...``) and the workflow when it loads both ask this.

    Parameters
    ----------
    path : str or path-like
        The config file, named in the message as given.

    Returns
    -------
    str or None
        ``{path}: problem``.
    """
    import yaml

    file = Path(path)
    if not file.is_file():
        what = "is a folder" if file.is_dir() else "not found"
        return f"{path}: config file {what} (expected a YAML file, e.g. make run CONFIG=my.yaml)"
    try:
        doc = load_yaml(file.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError) as exc:
        return f"{path}: cannot read the config file: {exc}"
    except yaml.YAMLError as exc:
        return f"{path}: {yaml_problem(exc)}"
    if doc is not None and not isinstance(doc, dict):
        return f"{path}: expected a mapping of config sections, got {type(doc).__name__}"
    return None


__all__ = ["config_file_problem", "load_yaml", "yaml_problem"]
