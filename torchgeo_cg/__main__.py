"""``python -m torchgeo_cg``: the ``torchgeo-cg`` command."""

from torchgeo_cg.cli.main import main

__all__: list[str] = []

if __name__ == "__main__":
    raise SystemExit(main())
