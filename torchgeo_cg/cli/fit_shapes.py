"""``torchgeo-cg fit-shapes``: recover the report's Table 3 (shapes A–H) and print it."""

from __future__ import annotations

import argparse

__all__ = ["add_parser"]  # a command: `torchgeo-cg` calls its add_parser

#: The largest ``--steps`` accepted: far beyond convergence (lm needs 10), and small
#: enough that a typo cannot start a run that never ends.
_MAX_STEPS = 1_000_000


def _steps_argument(text: str) -> int:
    """Parse ``--steps``: an integer in ``[1, MAX_STEPS]``.

    Raises:
        argparse.ArgumentTypeError: not an integer, or out of range (argparse
            turns it into a one-line usage error).

    Example:
        >>> _steps_argument("25")
        25
        >>> _steps_argument("-1")
        Traceback (most recent call last):
        ...
        argparse.ArgumentTypeError: must be an integer in [1, 1000000], got -1
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if not 1 <= value <= _MAX_STEPS:
        raise argparse.ArgumentTypeError(f"must be an integer in [1, {_MAX_STEPS}], got {value}")
    return value


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
    p.add_argument("--steps", type=_steps_argument, default=None,
                   help="iterations, 1 to 1000000 "
                        "(default: the optimizer's: lm 10, adam 200, lbfgs 50)")
    p.set_defaults(func=_run)
