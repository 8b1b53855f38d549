"""``stillframe play DIR [--rate R] [--clock [HZ]] [--loop] [--topics T …] [--exclude T …]``:
republish a bag with its timing and recorded QoS, like ``ros2 bag play``."""

from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe play``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser(
        "play", help="republish a rosbag2 bag with its original timing and QoS, like ros2 bag play")
    parser.add_argument("bag", metavar="DIR", help="rosbag2 directory")
    parser.add_argument("-r", "--rate", type=float, default=1.0,
                        help="playback speed factor (default 1.0)")
    parser.add_argument("--clock", type=float, nargs="?", const=40.0, default=None, metavar="HZ",
                        help="publish the bag time on /clock at HZ (default 40 Hz); a /clock "
                             "recorded in the bag is then not played")
    parser.add_argument("-l", "--loop", action="store_true", help="play again and again")
    parser.add_argument("--topics", nargs="+", default=[], metavar="TOPIC",
                        help="play only these topics (each must be in the bag)")
    parser.add_argument("--exclude", "--exclude-topics", dest="exclude", nargs="+", default=[],
                        metavar="TOPIC", help="play every topic but these")
    parser.add_argument("-d", "--delay", type=float, default=1.0, metavar="S",
                        help="seconds to wait after creating the publishers (discovery), "
                             "default 1.0")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Play the bag until its end (or Ctrl-C); exit code 0, or a
    :class:`~stillframe.errors.BagError` naming samples that could not be played."""
    from stillframe.errors import BagError, InputError
    from stillframe.middleware.api import create_node, ok
    from stillframe.recording.player import Player

    if not args.delay >= 0:
        raise InputError(f"--delay must be >= 0 s, got {args.delay}")
    node = create_node("stillframe_player", argv=sys.argv[:1])
    try:
        player = Player(node, args.bag, rate=args.rate, clock_hz=args.clock, topics=args.topics,
                        exclude=args.exclude)
        for note in player.skipped.values():
            node.get_logger().info(note)
        player.wait(args.delay)
        while ok():
            player.play_once()
            if not args.loop:
                break
        interrupted = not ok()
        acked = interrupted or player.finish()
        node.get_logger().info(f"Published {player.published} messages"
                               + (" (interrupted)" if interrupted else "")
                               + ("" if acked else " (some not acknowledged by subscribers)"))
    finally:
        node.destroy_node()
    if player.dropped or player.problems:      # counted and said, never dropped silently
        raise BagError("; ".join(
            ([f"{args.bag}: could not play {sum(player.dropped.values())} messages: "
              + player.dropped_text()] if player.dropped else []) + player.problems))
    return 0
