"""Subcommands of the ``stillframe`` command; each module has ``register(subparsers)``."""
