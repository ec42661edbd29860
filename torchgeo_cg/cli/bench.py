"""``torchgeo-cg bench [--quick] [--only AREA ...]``: run the benchmarks, print the table.

The benchmarks live in the repository's ``benchmarks/`` folder, beside the
package in a source checkout (an editable install), not in the wheel. They are
found from the installed package's own location, never from the current
folder, and loaded from that path only.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from pathlib import Path

from torchgeo_cg.cli import CommandError

__all__ = ["add_parser"]  # a command: `torchgeo-cg` calls its add_parser

#: The one line printed when the benchmarks are not there (a wheel install).
_NEEDS_CHECKOUT = (
    "the benchmarks are not part of the installed package; they run from a source "
    "checkout installed with pip install -e '.[bench]'"
)


def _find_benchmarks() -> Path:
    """The ``benchmarks/`` folder of the source checkout this package is imported from.

    It is the folder beside the ``torchgeo_cg`` package directory, and counts only
    if that parent is a torchgeo_cg checkout (its ``pyproject.toml`` names the
    project), so an unrelated ``benchmarks`` folder in ``site-packages`` or in the
    current folder is never used.

    Raises:
        FileNotFoundError: not a source checkout (the wheel ships no benchmarks).

    Example:
        >>> _find_benchmarks().name  # in a checkout
        'benchmarks'
    """
    import torchgeo_cg

    root = Path(torchgeo_cg.__file__).resolve().parents[1]
    bench = root / "benchmarks"
    pyproject = root / "pyproject.toml"
    is_checkout = pyproject.is_file() and 'name = "torchgeo_cg"' in pyproject.read_text(
        encoding="utf-8"
    )
    if is_checkout and (bench / "run.py").is_file() and (bench / "harness.py").is_file():
        return bench
    raise FileNotFoundError(_NEEDS_CHECKOUT)


def _load_benchmarks(folder: Path):
    """Import ``folder/run.py`` as ``benchmarks.run``, with the package taken from ``folder``.

    Raises:
        RuntimeError: another ``benchmarks`` package is imported already.
    """
    loaded = sys.modules.get("benchmarks")
    if loaded is not None:
        where = Path(getattr(loaded, "__file__", "") or "").resolve().parent
        if where != folder.resolve():
            raise RuntimeError(f"another 'benchmarks' package is imported already, from {where}")
    else:
        spec = importlib.util.spec_from_file_location(
            "benchmarks", folder / "__init__.py", submodule_search_locations=[str(folder)]
        )
        package = importlib.util.module_from_spec(spec)
        sys.modules["benchmarks"] = package
        spec.loader.exec_module(package)
    return importlib.import_module("benchmarks.run")


def _run(args: argparse.Namespace) -> int:
    try:
        run = _load_benchmarks(_find_benchmarks())
    except (FileNotFoundError, RuntimeError) as exc:
        raise CommandError(str(exc)) from None
    known = run.areas()
    unknown = [a for a in args.only or [] if a not in known]
    if unknown:
        raise CommandError(
            f"unknown benchmark area {', '.join(map(repr, unknown))}; "
            f"the areas are {', '.join(known)}"
        )
    try:
        measured = run.run(args.only, args.quick, write=not args.no_write)
    except run.MissingPeer as exc:
        raise CommandError(str(exc)) from None
    run.print_table(measured)
    return 0


def add_parser(sub) -> None:
    """Add the ``bench`` subcommand to the ``torchgeo-cg`` subparsers ``sub``."""
    p = sub.add_parser("bench", help="run the benchmarks against the peer libraries "
                                     "(from a source checkout)")
    p.add_argument("--quick", action="store_true", help="smaller sizes, shorter timing")
    p.add_argument("--only", nargs="+", metavar="AREA", help="areas to run (default: all)")
    p.add_argument("--no-write", action="store_true", help="do not update BENCHMARKS.md")
    p.set_defaults(func=_run)
