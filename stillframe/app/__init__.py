"""The application: the ``stillframe`` command, its subcommands and the process launcher."""
