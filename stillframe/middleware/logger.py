"""Node loggers printing in rcutils' default console format ``[LEVEL] [time] [name]: message``."""

from __future__ import annotations

import sys
import time

LEVELS = {"debug": 10, "info": 20, "warn": 30, "error": 40, "fatal": 50}


class Logger:
    """A named logger with rclpy's methods (``debug``, ``info``, ``warning``, ``error``, ...)."""

    def __init__(self, name: str, level: str = "info") -> None:
        self.name = name
        self.level = LEVELS[level if level in LEVELS else "info"]
        self._said: set[tuple[str, str]] = set()

    def log(self, severity: str, message: str, once: bool = False) -> bool:
        """Print ``message`` if ``severity`` passes the level (and, with ``once``, only once)."""
        if LEVELS[severity] < self.level:
            return False
        if once:
            if (severity, message) in self._said:
                return False
            self._said.add((severity, message))
        now = time.time_ns()
        stamp = f"{now // 1_000_000_000}.{now % 1_000_000_000:09d}"
        line = f"[{severity.upper()}] [{stamp}] [{self.name}]: {message}"
        print(line, file=sys.stderr, flush=True)
        return True

    def debug(self, message: str, once: bool = False) -> bool:
        """Print ``message`` at DEBUG level (see :meth:`log`); True when it was printed."""
        return self.log("debug", message, once)

    def info(self, message: str, once: bool = False) -> bool:
        """Print ``message`` at INFO level (see :meth:`log`); True when it was printed."""
        return self.log("info", message, once)

    def warning(self, message: str, once: bool = False) -> bool:
        """Print ``message`` at WARN level (see :meth:`log`); True when it was printed. ``warn`` is
        the same method."""
        return self.log("warn", message, once)

    warn = warning

    def error(self, message: str, once: bool = False) -> bool:
        """Print ``message`` at ERROR level (see :meth:`log`); True when it was printed."""
        return self.log("error", message, once)

    def fatal(self, message: str, once: bool = False) -> bool:
        """Print ``message`` at FATAL level (see :meth:`log`); True when it was printed."""
        return self.log("fatal", message, once)
