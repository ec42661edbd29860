"""Loop subdivision of triangle meshes as a sparse operator (Loop 1987; OpenSubdiv "Loop").

Built like :mod:`torchgeo_cg.mesh.subdivision.catmark`: the topology gives a sparse
``(V1, V0)`` matrix once, the geometry is refined by ``V1 = S @ V0``.

Convention:
    - Faces are ``(F, 3)`` long triangles (or lists of 3 indices), counter-clockwise
      seen from outside; output faces ``(4 F, 3)`` keep the winding. Face ``f``
      becomes faces ``4f .. 4f+3``: ``(v0, e01, e20)``, ``(v1, e12, e01)``,
      ``(v2, e20, e12)``, ``(e01, e12, e20)``.
    - New vertex order: the ``V0`` vertex points (old vertex ``i`` stays ``i``),
      then the ``E0`` edge points, edges sorted by ``(min, max)``. ``V1 = V0 + E0``.
    - Rules (untagged): an edge with exactly two consistently wound faces is smooth,
      any other is sharp; non-manifold vertices are corners (OpenSubdiv). Tags,
      holes and ``crease_method`` as in :mod:`torchgeo_cg.mesh.subdivision.catmark`.
      Smooth edge point ``3/8 (a + b) + 1/8 (c + d)`` (``c, d`` the opposite
      corners); sharp edge point ``1/2 (a + b)``. Vertex with ``n`` edges and ``s``
      sharp ones: ``s <= 1``: ``(1 - n beta) V + beta sum(nbrs)``,
      ``beta = (5/8 - (3/8 + 1/4 cos(2 pi / n))^2) / n``; ``s = 2``: ``3/4 V + 1/8 (a + b)``
      with ``a, b`` the sharp neighbours; ``s > 2``: kept; valence-2 boundary
      vertices kept with ``SchemeOptions(boundary="edge_and_corner")``. Unreferenced vertices pass
      through. Rows of ``S`` sum to 1, so the scheme is translation- and
      rotation-equivariant on open meshes too (trimesh's ``subdivide_loop`` is not).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from torchgeo_cg.core.check import ShapeError, check_float
from torchgeo_cg.core.numerics import working_dtype
from torchgeo_cg.mesh.faces import check_faces
from torchgeo_cg.mesh.subdivision._creasing import child_tags, subdivision_rules
from torchgeo_cg.mesh.subdivision._levels import SubdivisionModule
from torchgeo_cg.mesh.subdivision._limit_masks import loop_beta
from torchgeo_cg.mesh.subdivision._parallel_edges import loop_child_edge_tags
from torchgeo_cg.mesh.subdivision._stencil_build import stencil_matrix, weights_dtype
from torchgeo_cg.mesh.subdivision._topology import mesh_topology
from torchgeo_cg.mesh.subdivision.operator import SubdivisionOperator
from torchgeo_cg.mesh.subdivision.options import SchemeOptions
from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags

__all__ = ["loop_operator", "loop_subdivide", "LoopSubdivision"]


def loop_operator(
    faces: torch.Tensor | Sequence[Sequence[int]],
    num_vertices: int,
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
    tags: SubdivisionTags | None = None,
    edge_tags: torch.Tensor | None = None,
    *,
    options: SchemeOptions = SchemeOptions(),
) -> SubdivisionOperator:
    """Build one level of Loop subdivision as a sparse ``(V1, V0)`` matrix.

    Convention:
        See the module docstring (rules and new-vertex order). Vectorized
        sort/unique/bincount build under ``torch.no_grad()``.

    Args:
        faces: ``(F, 3)`` long triangles, or a list of index triples.
        num_vertices: ``V0``.
        device: device of the operator (default: that of ``faces``).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` (creases, corners, holes)
            or ``None``; sharpness follows OpenSubdiv (OpenSubdiv's creasing rules).
        edge_tags: ``(3 F,)`` long per corner of ``faces`` or ``None``: the previous
            operator's ``child_edge_tags`` when ``faces`` is its ``child_faces``.
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` (boundary,
            crease method; Loop ignores the triangle rule); the defaults are OpenSubdiv's.

    Returns:
        :class:`~torchgeo_cg.mesh.subdivision.SubdivisionOperator` with ``matrix``
        ``(V0 + E0, V0)`` and ``faces`` ``(4 F, 3)``; ``num_faces_in = F``.

    Raises:
        ShapeError: faces are not triangles.
        TypeError: ``options`` is not a :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions`.
        ValueError: indices out of range or negative (the message
            names the face). Repeated vertices and repeated faces are refined as
            OpenSubdiv refines them (as :func:`catmull_clark_operator` does).
        TypeError, ShapeError: a tags field of the wrong dtype or shape (named).
        TypeError: ``dtype`` is not a floating-point dtype.

    Example:
        >>> op = loop_operator([[0, 1, 2], [0, 2, 3]], 4)
        >>> op.matrix.shape, op.faces.shape
        (torch.Size([9, 4]), torch.Size([8, 3]))
        >>> op.matrix.to_dense()[5]  # the shared edge (0, 2): 3/8, 3/8 and 1/8, 1/8
        tensor([0.3750, 0.1250, 0.3750, 0.1250])
        >>> from torchgeo_cg.mesh.subdivision.tags import SubdivisionTags
        >>> sharp = SubdivisionTags.empty()._replace(
        ...     creases=torch.tensor([[0, 2]]), crease_sharpness=torch.tensor([0.5]))
        >>> loop_operator([[0, 1, 2], [0, 2, 3]], 4, tags=sharp).matrix.to_dense()[5]
        tensor([0.4375, 0.0625, 0.4375, 0.0625])
    """
    options = SchemeOptions.check(options)
    boundary, crease_method = options.boundary, options.crease_method
    with torch.no_grad():
        faces_f3 = check_faces(faces, num_vertices, allow_duplicates=True, allow_degenerate=True)
        if faces_f3.shape[0] and (faces_f3.shape[1] != 3 or bool((faces_f3 < 0).any())):
            raise ShapeError(
                f"faces: Loop subdivision needs triangles (F, 3), got polygons of up to "
                f"{faces_f3.shape[1]} vertices"
            )
        faces_f3 = faces_f3.reshape(-1, 3)
        if device is not None:
            faces_f3 = faces_f3.to(device)
        dev = faces_f3.device
        wdtype = weights_dtype(dtype)
        V0, F0 = num_vertices, faces_f3.shape[0]
        topo = mesh_topology(faces_f3, V0, boundary, edge_tags)
        E0 = topo.edge_lo_e.numel()
        V1 = V0 + E0
        rules = subdivision_rules(topo, V0, F0, tags, boundary, crease_method, wdtype)
        e_all = torch.arange(E0, device=dev)
        crease_e = rules.crease_e

        # Edge points: crease_e of 1/2 ends + (1 - crease_e) of 3/8 ends, 1/8 opposite.
        end_e = 0.5 * crease_e + 0.375 * (1.0 - crease_e)
        opposite_c = topo.vert_c[topo.prev_corner_c]  # corner opposite half-edge c
        smooth_c = (1.0 - crease_e)[topo.edge_c]

        # Vertex points: smooth (1 - n beta) V + beta sum, crease 3/4 V + 1/8 (a + b), corner V.
        n_v = topo.valence_v.to(wdtype).clamp(min=1)
        beta_v = loop_beta(n_v)
        self_v = rules.smooth_v * (1.0 - n_v * beta_v) + 0.75 * rules.crease_v + rules.corner_v
        lo_e, hi_e = topo.edge_lo_e, topo.edge_hi_e
        side_lo = rules.smooth_v[lo_e] * beta_v[lo_e] + rules.crease_end_lo_e
        side_hi = rules.smooth_v[hi_e] * beta_v[hi_e] + rules.crease_end_hi_e

        v_all = torch.arange(V0, device=dev)
        stencils = stencil_matrix(
            torch.cat([v_all, lo_e, hi_e, V0 + e_all, V0 + e_all, V0 + topo.edge_c]),
            torch.cat([v_all, hi_e, lo_e, lo_e, hi_e, opposite_c]),
            torch.cat([self_v, side_lo, side_hi, end_e, end_e, 0.125 * smooth_c]),
            (V1, V0),
        )
        # corners are face-major: corner 3f + k is vertex k of face f
        edge_fk = V0 + topo.edge_c.reshape(F0, 3)  # e01, e12, e20
        faces_f43 = torch.stack(
            [
                torch.stack([faces_f3[:, 0], edge_fk[:, 0], edge_fk[:, 2]], dim=1),
                torch.stack([faces_f3[:, 1], edge_fk[:, 1], edge_fk[:, 0]], dim=1),
                torch.stack([faces_f3[:, 2], edge_fk[:, 2], edge_fk[:, 1]], dim=1),
                edge_fk,
            ],
            dim=1,
        )
        faces_f3_all = faces_f43.reshape(-1, 3)
        hole_child = rules.hole_f.repeat_interleave(4)
        tags_1 = child_tags(rules, lo_e, hi_e, V0 + e_all, hole_child, tags)
    visible = faces_f3_all if tags_1 is None or tags_1.holes.numel() == 0 else (
        faces_f3_all[~hole_child]
    )
    return SubdivisionOperator(
        stencils, visible, V0, V1, F0, E0, boundary, "loop", faces_f3_all, tags_1,
        loop_child_edge_tags(faces_f3, topo, rules.inherit_e),
    )


class LoopSubdivision(SubdivisionModule):
    """Loop subdivision, ``levels`` steps, operators built once and cached as buffers.

    Convention:
        See the module docstring; same caching, ``.to()`` and backward (cached
        ``S^T``) as :class:`~torchgeo_cg.mesh.subdivision.CatmullClark`.

    Args:
        faces: ``(F, 3)`` long triangles, or a list of index triples.
        num_vertices: ``V``.
        levels: number of steps, ``>= 0`` (default 1).
        device: device of the buffers (default: that of ``faces``).
        dtype: dtype of the weights (default: ``torch.get_default_dtype()``).
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` (creases, corners, holes)
            or ``None``; sharpness follows OpenSubdiv (OpenSubdiv's creasing rules).
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` (boundary,
            crease method; Loop ignores the triangle rule); the defaults are OpenSubdiv's.

    Shape:
        - forward input ``verts``: ``(*, V, D)`` float, any ``D``.
        - forward output: ``(*, V_L, D)``; ``.faces``: ``(4^L F, 3)`` long.
        - forward ``out`` (optional): a ``(*, V_L, D)`` buffer of ``verts``' dtype and
          device that takes the result (outside autograd, eager only; see
          :func:`~torchgeo_cg.mesh.subdivision.apply_operator`).

    Example:
        >>> loop = LoopSubdivision([[0, 1, 2]], 3, levels=2)
        >>> loop(torch.rand(4, 3, 2)).shape, loop.faces.shape
        (torch.Size([4, 15, 2]), torch.Size([16, 3]))
    """

    _build_operator = staticmethod(loop_operator)
    scheme = "loop"


def loop_subdivide(
    verts: torch.Tensor,
    faces: torch.Tensor | Sequence[Sequence[int]],
    levels: int = 1,
    tags: SubdivisionTags | None = None,
    *,
    options: SchemeOptions = SchemeOptions(),
) -> tuple[torch.Tensor, torch.Tensor]:
    """Loop-subdivide ``levels`` times; convenience wrapper over :class:`LoopSubdivision`.

    Convention:
        See the module docstring.

    Args:
        verts: ``(*, V, D)`` float, a batch of shapes sharing ``faces``. float16 and
            bfloat16 are refined in float32 (weights and sums) and returned in their dtype.
        faces: ``(F, 3)`` long triangles on the device of ``verts``, or a list.
        levels: number of steps, ``>= 0``.
        tags: :class:`~torchgeo_cg.mesh.subdivision.SubdivisionTags` or ``None`` (see
            :func:`loop_operator`); carried from level to level.
        options: the :class:`~torchgeo_cg.mesh.subdivision.SchemeOptions` (boundary,
            crease method; Loop ignores the triangle rule); the defaults are OpenSubdiv's.

    Returns:
        ``(verts (*, V_L, D), faces (4^L F, 3) long)``.

    Raises:
        TypeError: ``verts`` is not a floating-point tensor.

    Example:
        >>> tri = torch.tensor([[0., 0.], [4., 0.], [0., 4.]])
        >>> v, f = loop_subdivide(tri, [[0, 1, 2]])
        >>> v[3:]  # boundary edge points: midpoints
        tensor([[2., 0.],
                [0., 2.],
                [2., 2.]])
    """
    check_float(verts, "verts")
    if isinstance(faces, torch.Tensor) and faces.device != verts.device:
        raise ValueError(
            f"verts and faces must be on the same device, got {verts.device} and {faces.device}"
        )
    if verts.dim() < 2:
        raise ShapeError(f"verts: expected shape (*, V, D), got {tuple(verts.shape)}")
    module = LoopSubdivision(faces, verts.shape[-2], levels=levels, device=verts.device,
                             dtype=working_dtype(verts.dtype), tags=tags, options=options)
    return module(verts), module.faces
