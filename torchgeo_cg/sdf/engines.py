"""Search backends of the mesh queries: the torch search or a compiled engine.

A backend answers one question, "which face is closest to each point" (piecewise
constant, no gradient); :func:`~torchgeo_cg.sdf.mesh_distance.mesh_sdf` evaluates the
distance on that face in torch. Backends:

- ``"torch"``: :mod:`~torchgeo_cg.sdf._mesh_search`, exact float64 search on the CPU
  (always installed).
- ``"warp"``: :mod:`~torchgeo_cg.sdf._engine_warp`, NVIDIA Warp's BVH (float32) with a
  float64 check of the neighbouring faces; CPU or CUDA; the optional extra ``fast``.
- ``"auto"``: the fastest installed engine that imports (:data:`ENGINES` is ordered by
  speed), else ``"torch"``. An engine that is installed but fails to import or
  initialise (a broken CUDA driver, a missing system library) is skipped with one
  ``UserWarning`` per process naming the failure; ``backend="warp"`` then raises an
  ``ImportError`` saying so, chained from the original exception.

The search itself (:mod:`~torchgeo_cg.sdf._closest_faces`) is a ``torch.library`` custom
op (``torchgeo_cg::closest_faces``) with a batching rule, so ``mesh_sdf`` works under
``torch.func.vmap`` and ``jacrev``.

Convention:
    Vertices ``(B, V, 3)`` share triangles ``(T, 3)``; points ``(B, N, 3)``; the result is
    ``(B, N)`` long face indices on the points' device.
"""

from __future__ import annotations

import importlib.util

from torchgeo_cg.engine import warp_status

__all__ = ["ENGINES", "available_engines"]

#: Engine name -> the module that must be importable, fastest first.
ENGINES = {"warp": "warp"}


def available_engines() -> list[str]:
    """Installed engines that import, fastest first.

    Convention:
        Names as accepted by ``mesh_sdf(backend=...)``; ``"torch"`` (always there) is not
        listed. The engines come with the optional extra ``fast``; an installed engine
        whose import failed is not listed (``backend="auto"`` warns about it once).

    Returns:
        A list of engine names, a subset of :data:`ENGINES`.

    Example:
        >>> set(available_engines()) <= set(ENGINES)
        True
    """
    return [name for name in _installed() if _import_error(name) is None]


def _installed() -> list[str]:
    """Engines whose module is installed (found, not imported) and not disabled, fastest
    first."""
    return [name for name, module in ENGINES.items()
            if (name == "warp" and warp_status()[0] != "missing")
            or (name != "warp" and importlib.util.find_spec(module) is not None)]


def _import_error(name: str) -> Exception | None:
    """The exception the import or initialisation of installed engine ``name`` raised,
    else None (Warp is loaded once per process by :func:`torchgeo_cg.engine.load_warp`)."""
    status, why = warp_status() if name == "warp" else ("ok", None)
    return why if status == "broken" else None
