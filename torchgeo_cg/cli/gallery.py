"""``torchgeo-cg gallery [--out DIR] [--section S ...]``: write the figures and index.html."""

from __future__ import annotations

import argparse

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    from torchgeo_cg.viz.gallery import build_gallery

    paths = build_gallery(args.out, sections=args.section, progress=not args.no_progress)
    print(f"wrote {len(paths) - 1} figures and {paths[-1]}")
    return 0


def add_parser(sub) -> None:
    """Add the ``gallery`` subcommand to the ``torchgeo-cg`` subparsers ``sub``."""
    p = sub.add_parser("gallery", help="render the figure gallery (PNG/GIF + index.html)")
    p.add_argument("--out", default="gallery", help="output folder (default: ./gallery)")
    p.add_argument("--section", nargs="*", default=None, help="only these sections")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=_run)
