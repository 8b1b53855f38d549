"""``stillframe netns up|down|list``: the three-host lab of ``launch --netns`` by hand.

``up`` makes the namespaces ``P-sim``, ``P-est``, ``P-ctl`` and the bridge ``P-br``
(:mod:`stillframe.app.netns_lab`) and prints how to run a node on a host; ``down`` removes
them (also what a killed launch left behind); ``list`` shows the labs present. Needs root.
"""

from __future__ import annotations

import argparse
import sys

from stillframe.app.arguments import add_json_argument, emit_json


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe netns``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("netns", help="make or remove the three-host lab (network "
                                          "namespaces on a bridge; root)",
                            description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("action", choices=("up", "down", "list"))
    parser.add_argument("--prefix", default=None, metavar="P",
                        help="name prefix (up: default sf<pid>; down: required)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Bring the three-host lab up or down, or list the labs present; exit code 0 (``up`` and
    ``down`` need root)."""
    from stillframe.app import netns_lab
    from stillframe.errors import InputError

    if args.action == "list":
        labs = sorted({n.rsplit("-", 1)[0] for n in netns_lab.namespaces()
                       if n.endswith(f"-{netns_lab.BRIDGE_HOST}")})
        if args.json:
            emit_json({"prefixes": labs})
        else:
            print("\n".join(labs) if labs else "no lab")
        return 0
    if args.action == "down":
        if args.prefix is None:
            raise InputError("netns down needs --prefix P (see `stillframe netns list`)")
        gone = netns_lab.down(args.prefix)
        if args.json:
            emit_json({"removed": gone})
        else:
            print(f"removed {', '.join(gone)}" if gone else f"no lab {args.prefix!r}")
        return 0
    made = netns_lab.up(args.prefix or netns_lab.default_prefix())
    hosts = {node: str(made.address(h)) for node, h in netns_lab.HOSTS.items()}
    if args.json:
        emit_json({"prefix": made.prefix, "subnet": str(made.subnet), "addresses": hosts,
                   "observer_interface": made.observer_interface})
        return 0
    print(f"lab {made.prefix}: {made.subnet}, this host on {made.observer_interface}")
    for node in netns_lab.HOSTS:
        print(f"  {node:15s} {hosts[node]:15s} {' '.join(made.prefix_of(node))} "
              f"{sys.executable} -m {node}.node --ros-args -p scene:=SCENE")
    print(f"remove it with: stillframe netns down --prefix {made.prefix}")
    return 0
