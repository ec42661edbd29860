"""The ``torchgeo-cg`` command.

Every other public module in :mod:`torchgeo_cg.cli` is a subcommand: it defines
``add_parser(subparsers)``, which adds its parser and sets ``func`` (a callable
taking the parsed ``argparse.Namespace`` and returning an exit code).

Errors never show a traceback: a bad argument, a
:class:`~torchgeo_cg.cli.CommandError` or an ``OSError`` (an output that
cannot be written) prints one line, ``torchgeo-cg <command>: error: ...``, on
stderr and exits non-zero (2 for usage errors, 1 for failures while running).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import torchgeo_cg.cli as cli
from torchgeo_cg.cli import CommandError

__all__ = ["main"]


class _OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr (exit 2), without usage.

    Subparsers made with ``add_subparsers`` inherit the class, so their errors
    name the subcommand (``torchgeo-cg gallery: error: ...``).

    Example:
        >>> import contextlib, io
        >>> parser = _OneLineParser(prog="demo")
        >>> _ = parser.add_argument("--n", type=int)
        >>> err = io.StringIO()
        >>> with contextlib.redirect_stderr(err):
        ...     try:
        ...         parser.parse_args(["--n", "x"])
        ...     except SystemExit as exc:
        ...         print(exc.code)
        2
        >>> err.getvalue()
        "demo: error: argument --n: invalid int value: 'x'\\n"
    """

    def error(self, message: str):  # noqa: D102 - argparse's hook
        self.exit(2, f"{self.prog}: error: {message}\n")


def _build_parser() -> argparse.ArgumentParser:
    """The ``torchgeo-cg`` parser, with one subparser per module of :mod:`torchgeo_cg.cli`."""
    parser = _OneLineParser(
        prog="torchgeo-cg",
        description="torchgeo_cg: batched, differentiable geometry in PyTorch.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for info in sorted(pkgutil.iter_modules(cli.__path__), key=lambda m: m.name):
        if info.name in {"main"} or info.name.startswith("_"):
            continue
        importlib.import_module(f"torchgeo_cg.cli.{info.name}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``torchgeo-cg`` console script.

    Returns the exit code: 0 on success, 2 for bad arguments, 1 when the command
    failed (an output could not be written, a figure failed), 130 on Ctrl-C and 141
    when the output pipe closes early.

    Example:
        >>> main(["info", "--brief"])  # doctest: +ELLIPSIS
        torchgeo_cg ... | torch ... | threads ... | devices cpu...
        0
    """
    args = _build_parser().parse_args(argv)
    prog = f"torchgeo-cg {args.command}"
    try:
        return int(args.func(args) or 0)
    except CommandError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # the reader went away (`| head`): stop quietly, as cat does
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:  # an output that cannot be written, a missing input file
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
