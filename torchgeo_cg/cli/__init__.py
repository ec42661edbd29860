"""The ``torchgeo-cg`` command line; each module is one subcommand."""

from torchgeo_cg.cli.main import main

__all__ = ["main"]
