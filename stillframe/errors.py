"""Errors that the command line reports as one clear line with exit code 2."""


class InputError(ValueError):
    """Bad input from a user: a scene value, a command-line argument, a file.

    The message names what is wrong (the key, the file, the value) and is printed without a
    traceback by :func:`stillframe.app.cli.main`.
    """
