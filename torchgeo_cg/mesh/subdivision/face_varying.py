"""Face-varying data (UVs with seams) subdivided by a second sparse operator.

A face-varying channel gives every face corner its own value index (``uv_faces``, padded
like ``faces``), so the values may jump across an edge: a *seam*. Following OpenSubdiv
(``Vtr::FVarLevel``), the channel is refined on its own topology, the *value mesh*: the
faces of ``uv_faces`` where a value index is made distinct per mesh vertex (a UV index
that two vertices share becomes two values). Seams are boundaries of the value mesh, and
the value mesh is refined by the same Catmark or Loop builders as the positions, with
tags that encode the chosen linear interpolation:

============================  ===========================================================
``fvar_interpolation``        OpenSubdiv ``FVarLinearInterpolation`` and what is pinned
============================  ===========================================================
``"none"``                    ``FVAR_LINEAR_NONE``: smooth everywhere; seams are smooth
                              boundary curves (crease rule), seam corners are smoothed.
``"corners_only"``            ``FVAR_LINEAR_CORNERS_ONLY``: a value in one face only
                              (a corner of a UV island) is kept.
``"corners_plus1"``           ``FVAR_LINEAR_CORNERS_PLUS1``: also every value of a
                              vertex where 3 or more values meet, and both values of a
                              2-value vertex where one value's faces are not one fan.
``"corners_plus2"``           ``FVAR_LINEAR_CORNERS_PLUS2``: also both values of a
                              2-value vertex when one is a corner, and interior darts
                              (a seam ending inside the mesh).
``"boundaries"``              ``FVAR_LINEAR_BOUNDARIES``: every value on a seam or mesh
                              boundary is kept; seam edges are linear.
``"all"``                     ``FVAR_LINEAR_ALL``: bilinear everywhere (face centroids,
                              edge midpoints, values kept).
============================  ===========================================================

Convention:
    - ``faces`` ``(F, K)`` and ``uv_faces`` ``(F, K)`` long are padded alike with ``-1``;
      corner ``k`` of face ``f`` has position ``faces[f, k]`` and value ``uv_faces[f, k]``.
    - The child value faces line up with the child position faces of
      :func:`~torchgeo_cg.mesh.subdivision.catmull_clark_operator` (or
      :func:`~torchgeo_cg.mesh.subdivision.loop.loop_operator`) built from the same ``faces``,
      ``options`` and ``tags``: same face order, same corner order, same holes left out.
    - Child value order: ``[value points (T') | face points (F) | edge points (E_uv)]``
      with ``T' >= T``; value ``i < T`` is the vertex point of input value ``i`` (for the
      first vertex using it), extra rows come from values shared by several vertices.
    - Where the channel is continuous, the position's rules apply (its creases, corners,
      holes, ``boundary`` corners and non-manifold vertices are carried onto the value
      mesh); where it is not, the value mesh's boundary rules apply. Infinitely sharp
      and untagged meshes follow OpenSubdiv exactly; a semi-sharp crease that ends on a
      seam uses the library's crease transition on the value mesh (OpenSubdiv blends its
      fractional weight per value, which can differ there).
    - Every row sums to 1: the operator is affine-invariant on the values (``D`` any).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import NamedTuple

import torch
from torch import nn

from torchgeo_cg.core.check import ShapeError, check_choice, check_float, check_shape
from torchgeo_cg.core.coerce import check_module_dtype
from torchgeo_cg.core.numerics import working_dtype
from torchgeo_cg.mesh.faces import check_faces, pad_faces
from torchgeo_cg.mesh.subdivision._creasing import subdivision_rules
from torchgeo_cg.mesh.subdivision._levels import children_options
from torchgeo_cg.mesh.subdivision._stencil_build import (
    StencilMatrix,
    check_out,
    stencil_matrix,
    weights_dtype,
)
from torchgeo_cg.mesh.subdivision._topology import mesh_topology
from torchgeo_cg.mesh.subdivision.catmark import catmull_clark_operator
from torchgeo_cg.mesh.subdivision.loop import loop_operator
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator
from torchgeo_cg.mesh.subdivision.options import SchemeOptions
from torchgeo_cg.mesh.subdivision.stencils import apply_stencils
from torchgeo_cg.mesh.subdivision.tags import INFINITELY_SHARP, SubdivisionTags

__all__ = [
    "face_varying_operator",
    "FaceVaryingSubdivision",
    "face_varying_subdivide",
]

_SCHEMES = ("catmark", "loop")
_CORNER_RULE = 2  # SubdivisionRules.rule_v: 0 smooth, 1 crease, 2 corner


class _ValueMesh(NamedTuple):
    """The value mesh of a face-varying channel (values made distinct per vertex).

    Attributes:
        faces: ``(F, K)`` long value ids, padded like the position faces.
        num_values: ``T' >= T``.
        source: ``(T',)`` long input value (UV index) of each value.
        vertex: ``(T',)`` long mesh vertex of each value (``-1`` for an unused input value).

    Example:
        >>> vm = _value_mesh(torch.tensor([[0, 1, 2], [0, 2, 3]]),
        ...                 torch.tensor([[0, 1, 2], [0, 2, 1]]), 4, 3)
        >>> vm.faces.tolist(), vm.num_values, vm.source.tolist(), vm.vertex.tolist()
        ([[0, 1, 2], [0, 2, 3]], 4, [0, 1, 2, 1], [0, 1, 2, 3])
    """

    faces: torch.Tensor
    num_values: int
    source: torch.Tensor
    vertex: torch.Tensor


def _value_mesh(faces_fk: torch.Tensor, uv_faces_fk: torch.Tensor, num_vertices: int,
               num_uvs: int) -> _ValueMesh:
    """Split value indices shared by several vertices (OpenSubdiv: a value belongs to a
    vertex); input value ``i`` keeps id ``i`` for its first vertex, extra ids follow.

    Args:
        faces_fk: ``(F, K)`` long position faces, padded with ``-1``.
        uv_faces_fk: ``(F, K)`` long value faces, padded alike.
        num_vertices: ``V``.
        num_uvs: ``T``.

    Returns:
        :class:`_ValueMesh`.
    """
    valid_fk = faces_fk >= 0
    vert_c, uv_c = faces_fk[valid_fk], uv_faces_fk[valid_fk]
    V = max(num_vertices, 1)
    key_u, inverse_c = torch.unique(uv_c * V + vert_c, return_inverse=True)
    uv_u, vert_u = key_u // V, key_u % V
    first_u = torch.ones_like(uv_u, dtype=torch.bool)
    first_u[1:] = uv_u[1:] != uv_u[:-1]
    value_u = torch.where(first_u, uv_u, num_uvs + torch.cumsum(~first_u, 0) - 1)
    num_values = num_uvs + int((~first_u).sum())
    value_fk = torch.full_like(faces_fk, -1)
    value_fk[valid_fk] = value_u[inverse_c]
    source = torch.arange(num_values, device=faces_fk.device)
    source[value_u] = uv_u
    vertex = torch.full((num_values,), -1, dtype=torch.long, device=faces_fk.device)
    vertex[value_u] = vert_u
    return _ValueMesh(value_fk, num_values, source, vertex)


def _per_end(lo_e, hi_e, mask_e, n: int) -> torch.Tensor:
    """``(n,)`` number of masked edges at each vertex."""
    return torch.bincount(torch.cat([lo_e[mask_e], hi_e[mask_e]]), minlength=n)


def _edge_sharpness(topo, tags: SubdivisionTags | None, V: int, dtype) -> torch.Tensor:
    """``(E,)`` crease-tag sharpness of the position edges (tags already validated)."""
    E = topo.edge_lo_e.numel()
    tag_e = torch.zeros(E, dtype=dtype, device=topo.edge_lo_e.device)
    if tags is None or tags.creases.numel() == 0 or E == 0:
        return tag_e
    creases = tags.creases.to(tag_e.device).long().reshape(-1, 2)
    key = creases.min(1).values * max(V, 1) + creases.max(1).values
    key_e = topo.edge_lo_e * max(V, 1) + topo.edge_hi_e  # sorted (unique)
    pos = torch.searchsorted(key_e, key).clamp(max=E - 1)
    sharp = tags.crease_sharpness.to(tag_e).reshape(-1)
    return tag_e.scatter_reduce(0, pos, sharp, "amax")


def _mode_corners(vm: _ValueMesh, uv_topo, uv_sharp_e, pos_boundary_v, interpolation: str):
    """``(T',)`` bool: values the interpolation mode pins (module table)."""
    T2, V = vm.num_values, pos_boundary_v.numel()
    used = vm.vertex >= 0
    vert = vm.vertex.clamp(min=0)
    on_seam = _per_end(uv_topo.edge_lo_e, uv_topo.edge_hi_e, uv_topo.sharp_e, T2) > 0
    if interpolation == "boundaries":
        return on_seam
    if interpolation == "corners_only":  # the value mesh's "edge_and_corner" pins them
        return torch.zeros_like(on_seam)
    count_v = torch.bincount(vert[used], minlength=V)
    count = count_v[vert]
    pinned = (count >= 3) & used
    disjoint = (_per_end(uv_topo.edge_lo_e, uv_topo.edge_hi_e, uv_sharp_e, T2) > 2) & used
    if interpolation == "corners_plus2":
        corner = (uv_topo.num_faces_v == 1) & (uv_topo.valence_v == 2)
        disjoint = disjoint | corner
        dart = used & (count == 1) & on_seam & ~pos_boundary_v[vert]
        pinned = pinned | dart
    pair_v = torch.bincount(vert[disjoint & (count == 2)], minlength=V) > 0
    return pinned | (pair_v[vert] & (count == 2) & used)


def _face_varying_tags(
    faces_fk: torch.Tensor,
    num_vertices: int,
    vm: _ValueMesh,
    interpolation: str,
    boundary: str,
    tags: SubdivisionTags | None,
    crease_method: str,
    dtype: torch.dtype,
) -> tuple[SubdivisionTags, str]:
    """Tags and boundary mode of the value mesh that give OpenSubdiv's face-varying rules.

    Convention:
        Position creases go to the value edges of the same corners, position corners
        (tagged, ``boundary="edge_and_corner"`` corners, non-manifold vertices) to every
        value of the vertex, holes stay holes; then the ``interpolation`` mode pins
        values (module table). ``"all"`` makes every value edge and value infinitely sharp.

    Args:
        faces_fk: ``(F, K)`` long position faces.
        num_vertices: ``V``.
        vm: :class:`_ValueMesh` of the channel.
        interpolation: one of :data:`FVAR_INTERPOLATIONS`.
        boundary: position boundary mode.
        tags: position :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` or ``None``.
        crease_method: ``"uniform"`` or ``"chaikin"``.
        dtype: float dtype of the sharpness.

    Returns:
        ``(value-mesh tags, value-mesh boundary mode)``.

    Example:
        >>> faces = torch.tensor([[0, 1, 4, 3], [1, 2, 5, 4]])  # no seam: values = vertices
        >>> vm = _value_mesh(faces, torch.tensor([[0, 1, 2, 3], [1, 4, 5, 2]]), 6, 6)
        >>> crease = SubdivisionTags.empty(torch.float64)._replace(
        ...     creases=torch.tensor([[1, 4]]), crease_sharpness=torch.tensor([2.0]).double())
        >>> uv_tags, mode = _face_varying_tags(faces, 6, vm, "boundaries", "edge_only", crease,
        ...                                   "uniform", torch.float64)
        >>> uv_tags.creases.tolist(), uv_tags.corners.tolist(), mode  # value 1-2 is edge 1-4
        ([[1, 2], [2, 1]], [0, 1, 2, 3, 4, 5], 'edge_and_corner')
    """
    V, F, T2 = num_vertices, faces_fk.shape[0], vm.num_values
    dev = faces_fk.device
    topo = mesh_topology(faces_fk, V, boundary)
    rules = subdivision_rules(topo, V, F, tags, boundary, crease_method, dtype)  # validates
    uv_topo = mesh_topology(vm.faces, T2, "edge_only")
    holes = torch.nonzero(rules.hole_f).flatten()
    inf = INFINITELY_SHARP
    if interpolation == "all":
        E2 = uv_topo.edge_lo_e.numel()
        return SubdivisionTags(
            torch.stack([uv_topo.edge_lo_e, uv_topo.edge_hi_e], 1),
            torch.full((E2,), inf, dtype=dtype, device=dev),
            torch.arange(T2, device=dev), torch.full((T2,), inf, dtype=dtype, device=dev),
            holes,
        ), "edge_only"
    # creases: the value edge of every corner whose position edge is creased
    crease_c = _edge_sharpness(topo, tags, V, dtype)[topo.edge_c]
    hit = crease_c > 0
    uv_creases = torch.stack([uv_topo.vert_c[hit], uv_topo.next_c[hit]], 1)
    uv_crease_e = torch.zeros(uv_topo.edge_lo_e.numel(), dtype=dtype, device=dev)
    uv_crease_e = uv_crease_e.scatter_reduce(0, uv_topo.edge_c[hit], crease_c[hit], "amax")
    # corners: tagged corner sharpness, then infinitely sharp position corners
    tag_v = torch.zeros(V, dtype=dtype, device=dev)
    if tags is not None and tags.corners.numel():
        tag_v = tag_v.scatter_reduce(0, tags.corners.to(dev).long().reshape(-1),
                                     tags.corner_sharpness.to(tag_v).reshape(-1), "amax")
    sharp_count_v = _per_end(topo.edge_lo_e, topo.edge_hi_e, rules.crease_e > 0, V)
    pos_inf_v = ((rules.rule_v == _CORNER_RULE) & (sharp_count_v <= 2) & (tag_v == 0)) | (
        topo.kind_v == 3)
    vert = vm.vertex.clamp(min=0)
    used = vm.vertex >= 0
    corner_s = torch.where(used & pos_inf_v[vert], inf, torch.where(used, tag_v[vert], 0.0))
    if interpolation != "none":
        uv_sharp_e = uv_topo.sharp_e | (uv_crease_e >= inf)
        pos_boundary_v = _per_end(topo.edge_lo_e, topo.edge_hi_e, topo.sharp_e, V) > 0
        pinned = _mode_corners(vm, uv_topo, uv_sharp_e, pos_boundary_v, interpolation)
        corner_s = torch.where(pinned, inf, corner_s)
    corners = torch.nonzero(corner_s > 0).flatten()
    uv_tags = SubdivisionTags(uv_creases, crease_c[hit], corners, corner_s[corners], holes)
    return uv_tags, ("edge_only" if interpolation == "none" else "edge_and_corner")


def _check_uv_faces(faces_fk: torch.Tensor, uv_faces, num_uvs: int) -> torch.Tensor:
    """``uv_faces`` padded, in range, and shaped and padded like ``faces``."""
    uv_fk = check_faces(pad_faces(uv_faces, device=faces_fk.device), num_uvs, "uv_faces",
                        allow_duplicates=True, allow_degenerate=True)
    if uv_fk.shape != faces_fk.shape and not (uv_fk.numel() == 0 and faces_fk.numel() == 0):
        raise ShapeError(f"uv_faces: expected the shape of faces {tuple(faces_fk.shape)}, "
                         f"got {tuple(uv_fk.shape)}")
    uv_fk = uv_fk.reshape(faces_fk.shape)
    bad = torch.nonzero(((uv_fk >= 0) != (faces_fk >= 0)).any(1)).flatten()
    if bad.numel():
        f = int(bad[0])
        none = "" if (uv_fk[f] >= 0).any() else (
            " (-1 on every corner: a face without texture coordinates, as load_mesh reads "
            "from an OBJ whose faces do not all have them; every face needs values here)")
        raise ValueError(f"uv_faces: face {f} has {int((uv_fk[f] >= 0).sum())} values but "
                         f"faces[{f}] has {int((faces_fk[f] >= 0).sum())} vertices{none}")
    return uv_fk


def _compose_columns(stencils: StencilMatrix, source: torch.Tensor, num_uvs: int
                     ) -> StencilMatrix:
    """``S @ P`` with ``P`` the ``(T', T)`` selection of each value's input value."""
    R = stencils.shape[0]
    rows = torch.repeat_interleave(torch.arange(R, device=stencils.crow.device),
                                   stencils.crow.diff())
    return stencil_matrix(rows, source[stencils.col], stencils.weights, (R, num_uvs))


def face_varying_operator(
    faces: torch.Tensor | Sequence[Sequence[int]],
    uv_faces: torch.Tensor | Sequence[Sequence[int]],
    num_vertices: int,
    num_uvs: int,
    scheme: str = "catmark",
    tags: SubdivisionTags | None = None,
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
    *,
    options: SchemeOptions = SchemeOptions(),
) -> SubdivisionOperator:
    """Build one level of face-varying subdivision as a sparse ``(T1, T)`` operator.

    Convention:
        See the module docstring: the value mesh is refined by the ``scheme``'s builder
        with tags from :func:`_face_varying_tags`; ``operator.faces`` are the child value
        faces, row for row and corner for corner those of the position operator built
        from ``(faces, num_vertices, tags, options)``. Apply it with
        :func:`~torchgeo_cg.mesh.subdivision.apply_operator`.

    Args:
        faces: ``(F, K)`` long position faces padded with ``-1``, or index lists
            (Loop: triangles).
        uv_faces: ``(F, K)`` long value (UV) indices per corner, padded like ``faces``.
        num_vertices: ``V``, number of positions.
        num_uvs: ``T``, number of input values.
        scheme: ``"catmark"`` (default) or ``"loop"``.
        tags: position :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` or ``None``.
        device: device of the operator (default: that of ``faces``).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions`: the position
            rules (boundary, crease method, triangle rule) and ``fvar_interpolation``.

    Returns:
        :class:`~torchgeo_cg.mesh.subdivision.SubdivisionOperator` with
        ``num_vertices_in = T``, ``num_vertices_out = T1``, ``faces`` ``(F1, 4)`` (Loop
        ``(F1, 3)``) child value faces and ``scheme``.

    Raises:
        TypeError: ``options`` is not a :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions`.
        ValueError: unknown ``scheme``; ``uv_faces`` out of range or
            padded unlike ``faces``; invalid faces or tags (the message names them).
        ShapeError: ``uv_faces`` not shaped like ``faces``.

    Example:
        >>> # two quads side by side with a UV seam along their shared edge (1, 4)
        >>> faces = [[0, 1, 4, 3], [1, 2, 5, 4]]
        >>> uv_faces = [[0, 1, 2, 3], [4, 5, 6, 7]]
        >>> from torchgeo_cg.mesh.subdivision import SchemeOptions
        >>> op = face_varying_operator(faces, uv_faces, 6, 8,
        ...                            options=SchemeOptions(fvar_interpolation="corners_only"))
        >>> op.num_vertices_in, op.num_vertices_out, op.faces.shape
        (8, 18, torch.Size([8, 4]))
        >>> uvs = torch.tensor([[0., 0.], [1., 0.], [1., 1.], [0., 1.],
        ...                     [2., 0.], [3., 0.], [3., 1.], [2., 1.]])
        >>> from torchgeo_cg.mesh.subdivision import apply_operator
        >>> apply_operator(op, uvs)[:4]  # island corners are kept
        tensor([[0., 0.],
                [1., 0.],
                [1., 1.],
                [0., 1.]])
    """
    check_choice(scheme, _SCHEMES, "scheme")
    options = SchemeOptions.check(options)
    boundary, crease_method = options.boundary, options.crease_method
    if isinstance(num_uvs, bool) or not isinstance(num_uvs, int) or num_uvs < 0:
        raise ValueError(f"num_uvs: expected an int >= 0, got {num_uvs!r}")
    wdtype = weights_dtype(dtype)
    with torch.no_grad():
        faces_fk = check_faces(faces, num_vertices)
        if device is not None:
            faces_fk = faces_fk.to(device)
        uv_fk = _check_uv_faces(faces_fk, uv_faces, num_uvs)
        vm = _value_mesh(faces_fk, uv_fk, num_vertices, num_uvs)
        uv_tags, uv_boundary = _face_varying_tags(faces_fk, num_vertices, vm,
                                                 options.fvar_interpolation, boundary, tags,
                                                 crease_method, wdtype)
        build = catmull_clark_operator if scheme == "catmark" else loop_operator
        op = build(vm.faces, vm.num_values, dtype=wdtype, tags=uv_tags,
                   options=replace(options, boundary=uv_boundary))
        stencils = op.stencils
        if vm.num_values != num_uvs:
            stencils = _compose_columns(stencils, vm.source, num_uvs)
    return op._replace(stencils=stencils, num_vertices_in=num_uvs, boundary=uv_boundary)


class FaceVaryingSubdivision(nn.Module):
    """Face-varying subdivision, ``levels`` steps, operators built once and cached.

    Convention:
        See the module docstring. Level ``l`` refines the value mesh alongside the
        position mesh of :class:`~torchgeo_cg.mesh.subdivision.CatmullClark` (or
        :class:`~torchgeo_cg.mesh.subdivision.loop.LoopSubdivision`) built with the same arguments,
        whose child faces and child tags it follows; ``.faces`` lines up with that
        module's ``.faces``. Buffers are plain non-persistent tensors (``.to()``,
        ``copy.deepcopy``, DDP).

    Args:
        faces: ``(F, K)`` long position faces padded with ``-1``, or index lists.
        uv_faces: ``(F, K)`` long value indices, padded like ``faces``.
        num_vertices: ``V``.
        num_uvs: ``T``.
        levels: number of steps, ``>= 0`` (default 1).
        scheme: ``"catmark"`` (default) or ``"loop"``.
        tags: position :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` or ``None``.
        device: device of the buffers (default: that of ``faces``).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions`: the position
            rules (boundary, crease method, triangle rule) and ``fvar_interpolation``.

    Shape:
        - forward input ``uvs``: ``(*, T, D)`` float, any ``D``.
        - forward output: ``(*, T_L, D)``; ``.faces``: ``(F_L, 4)`` (Loop ``(F_L, 3)``)
          long child value faces (the input ``uv_faces``, padded, when ``levels = 0``).

    Example:
        >>> fv = FaceVaryingSubdivision([[0, 1, 2, 3]], [[0, 1, 2, 3]], 4, 4, levels=2)
        >>> fv(torch.rand(4, 2)).shape, fv.faces.shape
        (torch.Size([25, 2]), torch.Size([16, 4]))
    """

    def __init__(
        self,
        faces: torch.Tensor | Sequence[Sequence[int]],
        uv_faces: torch.Tensor | Sequence[Sequence[int]],
        num_vertices: int,
        num_uvs: int,
        levels: int = 1,
        scheme: str = "catmark",
        tags: SubdivisionTags | None = None,
        device: torch.device | str | None = None,
        dtype: torch.dtype | None = None,
        *,
        options: SchemeOptions = SchemeOptions(),
    ) -> None:
        super().__init__()
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 0:
            raise ValueError(f"levels: expected an int >= 0, got {levels!r}")
        self.levels, self.scheme, self.options = levels, scheme, SchemeOptions.check(options)
        self.num_uvs_in = num_uvs
        faces_fk = check_faces(faces, num_vertices)
        if device is not None:
            faces_fk = faces_fk.to(device)
        uv_fk = _check_uv_faces(faces_fk, uv_faces, num_uvs)
        self.register_buffer("faces_0", uv_fk, persistent=False)
        count_v, count_t, level_options = num_vertices, num_uvs, options
        build = catmull_clark_operator if scheme == "catmark" else loop_operator
        for level in range(levels):  # loop over levels only
            op = face_varying_operator(faces_fk, uv_fk, count_v, count_t, scheme, tags=tags,
                                       dtype=dtype, options=level_options)
            pos = build(faces_fk, count_v, dtype=dtype, tags=tags, options=level_options)
            for field, tensor in zip(StencilMatrix._fields, op.stencils):
                self.register_buffer(f"{field}_{level}", tensor, persistent=False)
            self.register_buffer(f"faces_{level + 1}", op.faces, persistent=False)
            faces_fk, uv_fk, tags = pos.child_faces, op.child_faces, pos.child_tags
            count_v, count_t = pos.num_vertices_out, op.num_vertices_out
            level_options = children_options(options)
        self.num_uvs_out = count_t

    @property
    def faces(self) -> torch.Tensor:
        """``(F_L, K)`` long child value faces of the last level."""
        return getattr(self, f"faces_{self.levels}")

    def forward(self, uvs: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
        """Refine ``(*, T, D)`` -> ``(*, T_L, D)``; ``out`` (optional, ``(*, T_L, D)``) takes
        the last level's result as in
        :func:`~torchgeo_cg.mesh.subdivision.apply_operator` (outside autograd)."""
        check_module_dtype(self, uvs, "uvs")
        check_float(uvs, "uvs")
        check_shape(uvs, ["*", self.num_uvs_in, "D"], "uvs")
        if out is not None and self.levels == 0:
            check_out(out, tuple(uvs.shape), uvs)
            return out.copy_(uvs)
        for level in range(self.levels):
            stencils = StencilMatrix(
                *(getattr(self, f"{f}_{level}") for f in StencilMatrix._fields))
            last = level == self.levels - 1
            uvs = apply_stencils(stencils, uvs, out=out if last else None)
        return uvs

    def extra_repr(self) -> str:
        return (f"levels={self.levels}, scheme={self.scheme!r}, "
                f"options={self.options!r}, "
                f"num_uvs={self.num_uvs_in} -> {self.num_uvs_out}")


def face_varying_subdivide(
    uvs: torch.Tensor,
    faces: torch.Tensor | Sequence[Sequence[int]],
    uv_faces: torch.Tensor | Sequence[Sequence[int]],
    num_vertices: int,
    levels: int = 1,
    scheme: str = "catmark",
    tags: SubdivisionTags | None = None,
    *,
    options: SchemeOptions = SchemeOptions(),
) -> tuple[torch.Tensor, torch.Tensor]:
    """Subdivide face-varying values ``levels`` times (wrapper over
    :class:`FaceVaryingSubdivision`).

    Convention:
        See the module docstring; the returned faces line up with those of
        ``catmull_clark(verts, faces, levels, tags, options=options)``.

    Args:
        uvs: ``(*, T, D)`` float values (UVs: ``D = 2``); float16 and bfloat16 are
            refined in float32 and returned in their dtype.
        faces: ``(F, K)`` long position faces, or index lists.
        uv_faces: ``(F, K)`` long value indices padded like ``faces``.
        num_vertices: ``V``.
        levels: ``>= 0``.
        scheme, tags, options: as for :func:`face_varying_operator`.

    Returns:
        ``(uvs (*, T_L, D), uv_faces (F_L, 4) long)`` (Loop: ``(F_L, 3)``).

    Raises:
        TypeError: ``uvs`` is not a floating-point tensor.
        ShapeError: ``uvs`` is not ``(*, T, D)``.

    Example:
        >>> cube_f = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
        ...           [1, 5, 7, 3]]
        >>> uv_faces = [[4 * f + k for k in range(4)] for f in range(6)]  # 6 UV islands
        >>> square = torch.tensor([[0., 0.], [1., 0.], [1., 1.], [0., 1.]])
        >>> uv, uv_f = face_varying_subdivide(square.repeat(6, 1), cube_f, uv_faces, 8)
        >>> uv.shape, uv_f.shape, uv[uv_f[0]].tolist()  # "corners_only": corners kept
        (torch.Size([54, 2]), torch.Size([24, 4]), [[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5]])
    """
    check_float(uvs, "uvs")
    check_shape(uvs, ["*", "T", "D"], "uvs")
    module = FaceVaryingSubdivision(
        faces, uv_faces, num_vertices, uvs.shape[-2], levels, scheme, tags,
        device=uvs.device, dtype=working_dtype(uvs.dtype), options=options,
    )
    return module(uvs), module.faces
