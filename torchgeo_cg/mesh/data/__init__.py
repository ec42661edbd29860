"""Data shipped with the mesh package: ``rabbit.obj`` and the script that generates it."""

__all__: list[str] = []
