"""The ``torchgeo-cg`` command line; each module is one subcommand.

The entry point is :func:`torchgeo_cg.cli.main.main` (also ``python -m
torchgeo_cg`` and ``python -m torchgeo_cg.cli.main``). This package does not
import it, so running the ``main`` module with ``-m`` imports it only once.
"""

__all__ = ["CommandError"]


class CommandError(Exception):
    """A bad argument or an output that cannot be written.

    ``torchgeo-cg`` prints it as one line, ``torchgeo-cg <command>: error: <message>``,
    on stderr and exits with ``exit_code`` (2 by default, as argparse does), never
    with a traceback.

    Example:
        >>> err = CommandError("--steps must be at least 1, got -1")
        >>> str(err), err.exit_code
        ('--steps must be at least 1, got -1', 2)
    """

    def __init__(self, message: str, exit_code: int = 2) -> None:
        super().__init__(message)
        self.exit_code = exit_code
