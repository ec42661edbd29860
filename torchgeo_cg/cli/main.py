"""The ``torchgeo-cg`` command.

Every other module in :mod:`torchgeo_cg.cli` is a subcommand: it defines
``add_parser(subparsers)``, which adds its parser and sets ``func`` (a callable
taking the parsed ``argparse.Namespace`` and returning an exit code).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The ``torchgeo-cg`` parser, with one subparser per module of :mod:`torchgeo_cg.cli`."""
    import torchgeo_cg.cli as cli

    parser = argparse.ArgumentParser(
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

    Example:
        >>> main(["info", "--brief"])  # doctest: +ELLIPSIS
        torchgeo_cg ... | torch ... | threads ... | devices cpu...
        0
    """
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
