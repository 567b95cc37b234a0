"""Subcommands of the ``taplan`` CLI, one module each (``add_arguments``, ``run``)."""
