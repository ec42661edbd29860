"""``torchgeo-cg gallery [--out DIR] [--section S ...]``: write the figures and index.html."""

from __future__ import annotations

import argparse

from torchgeo_cg.cli import CommandError

__all__ = ["add_parser"]  # a command: `torchgeo-cg` calls its add_parser


def _run(args: argparse.Namespace) -> int:
    try:
        import matplotlib  # noqa: F401
        import PIL  # noqa: F401
    except ImportError:
        raise CommandError(
            "needs matplotlib and pillow: pip install 'torchgeo_cg[plot]'", exit_code=1
        ) from None
    from torchgeo_cg.viz.gallery import build_gallery, check_output_folder, check_sections

    try:
        out = check_output_folder(args.out)
        check_sections(args.section)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    try:
        paths = build_gallery(out, sections=args.section, progress=not args.no_progress)
    except RuntimeError as exc:  # some figures failed; the index lists them
        raise CommandError(str(exc), exit_code=1) from None
    print(f"wrote {len(paths) - 1} figures and {paths[-1]}")
    return 0


def add_parser(sub) -> None:
    """Add the ``gallery`` subcommand to the ``torchgeo-cg`` subparsers ``sub``."""
    p = sub.add_parser("gallery", help="render the figure gallery (PNG/GIF + index.html)")
    p.add_argument("--out", default="gallery", help="output folder (default: ./gallery)")
    p.add_argument("--section", nargs="+", default=None, metavar="SECTION",
                   help="only these sections (default: all)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=_run)
