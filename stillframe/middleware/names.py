"""ROS 2 names: validation and expansion of node names, namespaces and topic names (rcl rules)."""

from __future__ import annotations

import re

from stillframe.errors import InputError

_NODE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _tokens_ok(path: str) -> bool:
    return all(_TOKEN.fullmatch(token) for token in path.split("/"))


def validate_node_name(name: str) -> str:
    """``name`` if it is a valid ROS node name, else InputError."""
    if not _NODE.fullmatch(name):
        raise InputError(
            f"invalid node name {name!r}: letters, digits and '_' only, not starting with a digit"
        )
    return name


def validate_namespace(namespace: str) -> str:
    """The namespace made absolute (``frame`` -> ``/frame``); InputError if malformed."""
    namespace = "/" + namespace.strip("/") if namespace not in ("", "/") else "/"
    if namespace != "/" and not _tokens_ok(namespace[1:]):
        raise InputError(f"invalid namespace {namespace!r}: tokens of letters, digits, '_'")
    return namespace


def is_hidden(name: str) -> bool:
    """A name with a token starting with '_' is hidden (``ros2 topic list`` and ``ros2 bag record
    -a`` leave it out unless asked)."""
    return any(token.startswith("_") for token in name.split("/"))


def resolve_topic(name: str, namespace: str = "/", node_name: str = "") -> str:
    """The fully qualified topic name of ``name`` seen from a node (relative, ``~`` or absolute)."""
    if name.startswith("~"):
        base = namespace.rstrip("/") + "/" + node_name
        rest = name[1:]
        if rest and not rest.startswith("/"):
            raise InputError(f"invalid topic name {name!r}: '~' must be followed by '/'")
        full = base + rest
    elif name.startswith("/"):
        full = name
    else:
        full = namespace.rstrip("/") + "/" + name
    if (
        not name
        or full.endswith("/")
        or "//" in full
        or not _tokens_ok(full[1:])
    ):
        raise InputError(
            f"invalid topic name {name!r}: tokens of letters, digits and '_' separated by '/',"
            " not starting with a digit, no trailing '/'"
        )
    return full
