"""The environment is input: every variable stillframe reads, declared once with its check and
its documentation, as the scene's keys are (:mod:`stillframe.config.schema`).

:func:`check_environment` checks them all before anything starts (the ``stillframe`` command,
the node executables): a value a variable cannot take is one line naming the variable, exit code
2, where rcl or a DDS vendor would fail later with a traceback of its own (``ROS_STATIC_PEERS=
'$$$'``: an ``RCLError`` from Fast DDS), exit with a code of its own (``RMW_IMPLEMENTATION``:
rcl's 102) or take the value silently (``ROS_DOMAIN_ID=-1``). Code that reads a variable reads
it through :func:`value`, so it cannot read an unchecked one. ``python -m
stillframe.config.environment`` writes the table (:func:`reference`) into docs/middleware.md.
"""

from __future__ import annotations

import ipaddress
import math
import os
import re
import stat
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from stillframe.errors import InputError
from stillframe.text_table import with_section

Check = Callable[[str], str | None]

#: the largest ROS domain id with the default port mapping of Fast DDS and Cyclone DDS
#: (7400 + 250 * 232 + 11 is the last port below 65536 a participant of the domain uses)
MAX_DOMAIN_ID = 232
#: the discovery ranges of ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (rmw, Jazzy)
DISCOVERY_RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")
_RMW = re.compile(r"rmw_[a-z0-9_]+")


@dataclass(frozen=True)
class Variable:
    """One environment variable: its name, the check of a value (an error text or None; an
    empty or unset variable is its default and not checked) and what it means."""

    name: str
    check: Check
    doc: str
    default: str = ""


def _accepting(check: Check, accepts: str) -> Check:
    """``check`` with what it accepts in words (its docstring: the reference's column)."""
    check.__doc__ = accepts
    return check


def one_of(*choices: str) -> Check:
    """A check accepting exactly one of ``choices``; its docstring lists them for the reference."""
    def check(text: str) -> str | None:
        return None if text in choices else f"expected one of {', '.join(choices)}"

    return _accepting(check, ", ".join(f"`{c}`" for c in choices))


def whole_number(low: int, high: int) -> Check:
    """A check accepting a decimal integer in ``low..high`` (digits only, no sign)."""
    def check(text: str) -> str | None:
        ok = text.isascii() and text.isdigit() and low <= int(text) <= high
        return None if ok else f"expected an integer {low}..{high}"

    return _accepting(check, f"an integer {low}..{high}")


def seconds(high: float) -> Check:
    """A check accepting a number of seconds in (0, ``high``]."""
    def check(text: str) -> str | None:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        return None if 0 < value <= high else f"expected seconds in (0, {high:g}]"

    return _accepting(check, f"seconds in (0, {high:g}]")


def _host(text: str) -> bool:
    """A host name (RFC 1123 labels) or an IPv4 or IPv6 address."""
    try:
        ipaddress.ip_address(text.strip("[]"))
        return True
    except ValueError:
        pass
    return len(text) <= 253 and all(_LABEL.fullmatch(part) for part in text.rstrip(".").split("."))


def hosts(text: str) -> str | None:
    """host names or IP addresses, separated by `;`"""
    bad = [part.strip() for part in text.split(";") if part.strip() and not _host(part.strip())]
    return None if not bad else f"{bad[0][:60]!r} is not a host name or an IP address"


def rmw_name(text: str) -> str | None:
    """an rmw rclpy can load (`rmw_...`)"""
    return None if _RMW.fullmatch(text) else "expected an rmw implementation, e.g. rmw_fastrtps_cpp"


def a_directory(text: str) -> str | None:
    """a directory"""
    try:
        return None if stat.S_ISDIR(os.stat(text).st_mode) else "not a directory"
    except OSError as exc:
        return f"not a directory ({exc.strerror})"


VARIABLES: tuple[Variable, ...] = (
    Variable("ROS_DOMAIN_ID", whole_number(0, MAX_DOMAIN_ID), default="0", doc=(
        "the DDS domain of every node and tool (default port mapping of Fast DDS and "
        "Cyclone DDS)")),
    Variable("ROS_AUTOMATIC_DISCOVERY_RANGE", one_of(*DISCOVERY_RANGES), default="SUBNET",
             doc="how far discovery reaches (docs/middleware.md, Discovery)"),
    Variable("ROS_LOCALHOST_ONLY", one_of("0", "1"), default="0", doc=(
        "1: LOCALHOST when ROS_AUTOMATIC_DISCOVERY_RANGE is unset (deprecated in Jazzy, still "
        "honoured by rcl)")),
    Variable("ROS_STATIC_PEERS", hosts, doc=(
        "hosts to discover by unicast, separated by semicolons (with SUBNET and LOCALHOST)")),
    Variable("RMW_IMPLEMENTATION", rmw_name, doc=(
        "rclpy's middleware; it must be the one rclpy was built with or can load (checked "
        "before rclpy is imported: rcl ends a process whose value it cannot load with exit code "
        "102); the dds backend ignores it")),
    Variable("CYCLONEDDS_URI", _accepting(lambda text: None, "what Cyclone DDS takes"), doc=(
        "the dds backend's own Cyclone DDS configuration (files or XML), after stillframe's")),
    Variable("STILLFRAME_RMW", one_of("dds", "rclpy"), doc=(
        "the middleware backend of a process: dds, or rclpy (default: rclpy where it can be "
        "imported, else dds)")),
    Variable("STILLFRAME_VERBOSE", one_of("0", "1"), default="0", doc=(
        "1: the command-line tools' own nodes log their backend (set by stillframe --verbose)")),
    Variable("STILLFRAME_DAEMON_IDLE_S", seconds(1e6), default="7200", doc=(
        "seconds the graph daemon (stillframe daemon) waits for a question before it stops "
        "(two hours, as ros2 daemon)")),
    Variable("STILLFRAME_DATASETS", a_directory, doc=(
        "a folder of datasets in place of the checkout's datasets/ (identify-daisy)")),
)
#: the variables by name
BY_NAME: dict[str, Variable] = {v.name: v for v in VARIABLES}


def problem(variable: Variable, text: str) -> str | None:
    """The one-line error of ``text`` as ``variable``'s value, or None."""
    if not text:
        return None
    found = variable.check(text)
    if found is None:
        return None
    shown = text if len(text) <= 60 else text[:59] + "…"
    return f"{variable.name}={shown!r}: {found}"


def value(name: str, environ: Mapping[str, str] | None = None) -> str:
    """The variable's value (stripped; its default when unset or empty), checked: InputError
    naming it when the value is not one it can take."""
    variable = BY_NAME[name]
    text = (os.environ if environ is None else environ).get(name, "").strip()
    found = problem(variable, text)
    if found:
        raise InputError(found)
    return text or variable.default


def is_set(name: str) -> bool:
    """Whether the variable holds a value (not unset, not empty)."""
    return bool(os.environ.get(BY_NAME[name].name, "").strip())


def check_environment(environ: Mapping[str, str] | None = None) -> None:
    """Every declared variable of ``environ`` (default: this process's): InputError naming the
    first that holds a value it cannot take."""
    for variable in VARIABLES:
        value(variable.name, environ)


def reference() -> str:
    """The variables as a Markdown table (docs/middleware.md)."""
    rows = ["| variable | accepts | default | meaning |", "|---|---|---|---|"]
    rows += [f"| `{v.name}` | {v.check.__doc__} | {f'`{v.default}`' if v.default else '—'} | "
             f"{v.doc} |" for v in VARIABLES]
    return "\n".join(rows) + "\n"


#: the lines between which docs/middleware.md holds :func:`reference`
REFERENCE_MARKERS = ("<!-- environment reference: generated from "
                     "stillframe/config/environment.py -->",
                     "<!-- end of the environment reference -->")


def with_reference(text: str) -> str:
    """``text`` (docs/middleware.md) with the table between its markers made anew."""
    return with_section(text, REFERENCE_MARKERS, reference())


if __name__ == "__main__":
    page = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/middleware.md")
    page.write_text(with_reference(page.read_text()))
