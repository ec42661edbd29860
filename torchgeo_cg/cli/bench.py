"""``torchgeo-cg bench [--quick] [--only AREA ...]``: run the benchmarks, print the table.

The benchmarks live in the repository's ``benchmarks/`` folder (next to the
package in a source checkout or editable install), not in the installed wheel.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_parser", "find_benchmarks"]


def find_benchmarks() -> Path:
    """The repository's ``benchmarks/`` folder.

    Raises:
        FileNotFoundError: not a source checkout (the wheel ships no benchmarks).
    """
    import torchgeo_cg

    for root in (Path(torchgeo_cg.__file__).resolve().parents[1], Path.cwd()):
        if (root / "benchmarks" / "run.py").is_file():
            return root / "benchmarks"
    raise FileNotFoundError(
        "bench: benchmarks/ not found; run from a source checkout of torchgeo_cg"
    )


def _run(args: argparse.Namespace) -> int:
    root = str(find_benchmarks().parent)
    if root not in sys.path:
        sys.path.insert(0, root)
    from benchmarks import run

    argv = (["--quick"] if args.quick else []) + (["--only", *args.only] if args.only else [])
    if args.no_write:
        argv.append("--no-write")
    return run.main(argv)


def add_parser(sub) -> None:
    """Add the ``bench`` subcommand to the ``torchgeo-cg`` subparsers ``sub``."""
    p = sub.add_parser("bench", help="run the benchmarks against the peer libraries")
    p.add_argument("--quick", action="store_true", help="smaller sizes, shorter timing")
    p.add_argument("--only", nargs="*", help="areas to run (default: all)")
    p.add_argument("--no-write", action="store_true", help="do not update BENCHMARKS.md")
    p.set_defaults(func=_run)
