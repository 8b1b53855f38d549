"""``stillframe interface show TYPE``: a message or service definition, shaped like ``ros2
interface show``: the type's fields, each nested message's fields below it indented by a tab.

The text is the definition held by ``rosbags``' Jazzy typestore (``generate_msgdef``), the one
stillframe's nodes speak and its bags record: fields and constants, without the comments of the
``.msg`` files (the typestore does not keep them). A service (``pkg/srv/Name``, the
``rcl_interfaces`` parameter services stillframe registers) shows its request and response
separated by ``---``.
"""

from __future__ import annotations

import argparse
import re

from stillframe.app.ros_tools import add_verbs
from stillframe.errors import InputError
from stillframe.middleware.graph import did_you_mean

SEPARATOR = "=" * 80
#: the message type of a field line (``pkg/Name``, with any array suffix)
FIELD_TYPE = re.compile(r"^(\S+?)(\[[^\]]*\])?\s")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe interface`` and its verbs (``show``) to ``sub``, each verb with its
    ``run_VERB`` as its action."""
    verbs = add_verbs(sub, "interface", "show message and service definitions (like ros2 "
                                        "interface)")
    show = verbs.add_parser("show", help="the definition of a message or service type")
    show.add_argument("type", metavar="TYPE", help="e.g. sensor_msgs/msg/Imu")
    show.set_defaults(func=run_show)


def sections(type_name: str) -> tuple[list[str], dict[str, list[str]]]:
    """The type's own lines and each nested type's lines (``pkg/Name`` -> lines), from the
    typestore's concatenated definition."""
    from stillframe.contract import messages

    text = messages.TYPESTORE.generate_msgdef(type_name, ros_version=2)[0]
    first, *rest = text.split(SEPARATOR + "\n")
    nested = {}
    for part in rest:
        header, _, body = part.partition("\n")
        nested[header.removeprefix("MSG: ")] = body.splitlines()
    return first.splitlines(), nested


def expand(lines: list[str], nested: dict[str, list[str]], depth: int = 0) -> list[str]:
    """``lines`` with every nested message's lines after its field, one tab deeper."""
    out = []
    for line in lines:
        out.append("\t" * depth + line)
        match = FIELD_TYPE.match(line)
        if match and match.group(1) in nested:
            out += expand(nested[match.group(1)], nested, depth + 1)
    return out


def definition(type_name: str) -> str:
    """What ``interface show`` prints for ``pkg/msg/Name`` or ``pkg/srv/Name``."""
    from stillframe.contract import messages

    known = messages.TYPESTORE.fielddefs
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "srv":
        if f"{type_name}_Request" not in known:
            services = sorted({t.rsplit("_", 1)[0] for t in known if "/srv/" in t})
            raise InputError(f"unknown service type {type_name}"
                             f"{did_you_mean(type_name, services)}")
        request, response = ("\n".join(expand(*sections(f"{type_name}_{part}")))
                             for part in ("Request", "Response"))
        return f"{request}\n---\n{response}"
    if type_name not in known:
        messages_ = sorted(t for t in known if "/msg/" in t)
        raise InputError(f"unknown message type {type_name}{did_you_mean(type_name, messages_)}")
    return "\n".join(expand(*sections(type_name)))


def run_show(args: argparse.Namespace) -> int:
    """``interface show TYPE``: print the definition of the message or service type; exit code 0."""
    print(definition(args.type))
    return 0
