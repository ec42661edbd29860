"""The scheme options of every subdivision builder and module, documented once.

One frozen bundle, :class:`SchemeOptions`, carries the rules a subdivision scheme is
built with, as OpenSubdiv's ``Sdc::Options`` does; every builder and module takes it as
``options=SchemeOptions(...)``.
"""

from __future__ import annotations

from dataclasses import dataclass

from torchgeo_cg.core.check import check_choice

__all__ = [
    "SchemeOptions",
    "BOUNDARY_MODES",
    "CREASE_METHODS",
    "TRIANGLE_RULES",
    "FVAR_INTERPOLATIONS",
]

#: values of ``SchemeOptions.boundary`` (OpenSubdiv ``VtxBoundaryInterpolation``)
BOUNDARY_MODES = ("edge_only", "edge_and_corner", "none")
#: values of ``SchemeOptions.crease_method`` (OpenSubdiv ``CreasingMethod``)
CREASE_METHODS = ("uniform", "chaikin")
#: values of ``SchemeOptions.triangle_rule`` (OpenSubdiv ``TriangleSubdivision``)
TRIANGLE_RULES = ("catmark", "smooth")
#: values of ``SchemeOptions.fvar_interpolation`` (OpenSubdiv ``FVarLinearInterpolation``)
FVAR_INTERPOLATIONS = (
    "none", "corners_only", "corners_plus1", "corners_plus2", "boundaries", "all"
)


@dataclass(frozen=True)
class SchemeOptions:
    """The rules of a subdivision scheme (OpenSubdiv's ``Sdc::Options``), validated once.

    Every field has OpenSubdiv's meaning and, but for ``fvar_interpolation``, its default.

    Attributes:
        boundary: how boundary vertices are refined (``VtxBoundaryInterpolation``):

            - ``"edge_only"`` (default, ``VTX_BOUNDARY_EDGE_ONLY``): boundary edges are
              infinitely sharp creases, so the boundary is a B-spline curve; a corner of
              valence 2 is smoothed along it.
            - ``"edge_and_corner"`` (``VTX_BOUNDARY_EDGE_AND_CORNER``): as
              ``"edge_only"``, and boundary vertices of valence 2 are infinitely sharp
              corners (kept in place).
            - ``"none"`` (``VTX_BOUNDARY_NONE``): faces touching an untagged boundary
              become holes (at the base level; their children stay holes).
        crease_method: how a semi-sharp crease's sharpness decays from level to level
            (``CreasingMethod``): ``"uniform"`` (default, ``CREASE_UNIFORM``: minus 1 per
            level) or ``"chaikin"`` (``CREASE_CHAIKIN``: the child edges average their
            neighbours' sharpness, as Chaikin's curve rule).
        triangle_rule: the edge-point weights next to triangles in Catmull-Clark
            (``TriangleSubdivision``; Loop ignores it): ``"catmark"`` (default,
            ``TRI_SUB_CATMARK``: the plain rule) or ``"smooth"`` (``TRI_SUB_SMOOTH``:
            weights that smooth the triangles' children).
        fvar_interpolation: the linear interpolation of face-varying channels (UVs),
            ``FVarLinearInterpolation``; one of :data:`FVAR_INTERPOLATIONS` (default
            ``"corners_only"``; OpenSubdiv's default is ``"all"``). What each pins is
            tabled in :mod:`torchgeo_cg.mesh.subdivision.face_varying`. Positions ignore it.

    Raises:
        ValueError: a field outside its values (the message names it and lists them).

    Example:
        >>> SchemeOptions()
        SchemeOptions(boundary='edge_only', crease_method='uniform', triangle_rule='catmark', fvar_interpolation='corners_only')
        >>> from dataclasses import replace
        >>> replace(SchemeOptions(), boundary="edge_and_corner").boundary
        'edge_and_corner'
        >>> SchemeOptions(crease_method="chaikn")
        Traceback (most recent call last):
        ...
        ValueError: crease_method: expected one of 'uniform', 'chaikin', got 'chaikn'
    """  # noqa: E501

    boundary: str = "edge_only"
    crease_method: str = "uniform"
    triangle_rule: str = "catmark"
    fvar_interpolation: str = "corners_only"

    def __post_init__(self) -> None:
        check_choice(self.boundary, BOUNDARY_MODES, "boundary")
        check_choice(self.crease_method, CREASE_METHODS, "crease_method")
        check_choice(self.triangle_rule, TRIANGLE_RULES, "triangle_rule")
        check_choice(self.fvar_interpolation, FVAR_INTERPOLATIONS, "fvar_interpolation")

    @classmethod
    def check(cls, options: object) -> SchemeOptions:
        """``options`` if it is a :class:`SchemeOptions`, else a ``TypeError`` naming it.

        Example:
            >>> SchemeOptions.check(SchemeOptions()).boundary
            'edge_only'
        """
        if not isinstance(options, cls):
            hint = (f" (the scheme options are one bundle: options=SchemeOptions(boundary="
                    f"{options!r}))" if isinstance(options, str) else "")
            raise TypeError(f"options: expected a SchemeOptions, got "
                            f"{type(options).__name__}{hint}")
        return options

