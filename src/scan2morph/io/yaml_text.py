"""YAML documents read for their values, refusing a key given twice, with readable errors."""

from __future__ import annotations


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


__all__ = ["load_yaml", "yaml_problem"]
