"""Subcommands of the ``nbcalib`` command line, one module each (see :mod:`nbcalib.cli`)."""
