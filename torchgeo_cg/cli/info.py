"""``torchgeo-cg info``: versions, devices and thread count."""

from __future__ import annotations

import argparse
import importlib
import platform

__all__ = ["add_parser"]  # a command: `torchgeo-cg` calls its add_parser

_PACKAGES = ("torch", "kornia", "numpy", "trimesh", "skimage", "scipy", "matplotlib")


def _collect_info() -> dict[str, object]:
    """Versions of torchgeo_cg and its dependencies, the devices and the threads.

    Example:
        >>> info = _collect_info()
        >>> info["devices"][0], info["threads"] >= 1
        ('cpu', True)
    """
    import torch

    import torchgeo_cg

    info: dict[str, object] = {
        "torchgeo_cg": torchgeo_cg.__version__,
        "python": platform.python_version(),
    }
    for name in _PACKAGES:
        try:
            info[name] = importlib.import_module(name).__version__
        except ImportError:
            info[name] = "not installed"
    devices = ["cpu"]
    if torch.cuda.is_available():
        devices += [
            f"cuda:{i} ({torch.cuda.get_device_name(i)})" for i in range(torch.cuda.device_count())
        ]
    info["devices"] = devices
    info["threads"] = torch.get_num_threads()
    return info


def _run(args: argparse.Namespace) -> int:
    info = _collect_info()
    if args.brief:
        print(
            f"torchgeo_cg {info['torchgeo_cg']} | torch {info['torch']} | "
            f"threads {info['threads']} | devices {', '.join(info['devices'])}"
        )
        return 0
    width = max(len(k) for k in info)
    for key, value in info.items():
        value = ", ".join(value) if isinstance(value, list) else value
        print(f"{key:<{width}}  {value}")
    return 0


def add_parser(sub) -> None:
    """Add the ``info`` subcommand to the ``torchgeo-cg`` subparsers ``sub``."""
    p = sub.add_parser("info", help="print versions, devices and thread count")
    p.add_argument("--brief", action="store_true", help="one line")
    p.set_defaults(func=_run)
