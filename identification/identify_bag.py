"""``identify_bag``: ``stillframe identify`` as a ROS 2 executable (``ros2 run identification
identify_bag BAG --input … --output …``); ``--ros-args …`` (which ``ros2 run`` may add) is
dropped, the rest is the command's own arguments, and its exit codes are the command's."""

from __future__ import annotations

import sys

from stillframe.app.cli import main as stillframe_main


def command_arguments(argv: list[str]) -> list[str]:
    """``argv`` without a ``--ros-args … [--]`` section."""
    if "--ros-args" not in argv:
        return list(argv)
    start = argv.index("--ros-args")
    end = argv.index("--", start) + 1 if "--" in argv[start:] else len(argv)
    return argv[:start] + argv[end:]


def main() -> int:
    """Run ``stillframe identify`` with the process's arguments (less ``--ros-args``); its exit
    code."""
    return stillframe_main(["identify", *command_arguments(sys.argv[1:])])


if __name__ == "__main__":
    sys.exit(main())
