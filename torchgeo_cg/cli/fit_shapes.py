"""``torchgeo-cg fit-shapes``: recover the report's Table 3 (shapes A–H) and print it."""

from __future__ import annotations

import argparse

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    from torchgeo_cg.transforms.report_shapes import fit_report_shapes, format_report_table

    fit = fit_report_shapes(optimizer=args.optimizer, steps=args.steps)
    print(format_report_table(fit))
    return 0


def add_parser(sub) -> None:
    """Add the ``fit-shapes`` subcommand to the ``torchgeo-cg`` subparsers ``sub``."""
    p = sub.add_parser(
        "fit-shapes",
        help="fit the report's shapes A-H in one batched call and print a Table-3-style summary",
    )
    p.add_argument("--optimizer", choices=["lm", "adam", "lbfgs"], default="lm",
                   help="optimizer of fit_transform (default: lm)")
    p.add_argument("--steps", type=int, default=None,
                   help="iterations (default: the optimizer's: lm 10, adam 200, lbfgs 50)")
    p.set_defaults(func=_run)
