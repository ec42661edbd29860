"""Point-cloud normals by PCA over the k nearest neighbours, batched and ragged.

Convention:
    - The neighbourhood of a point is its ``k`` nearest valid points (:func:`knn`, the
      point itself included). Its normal is the unit eigenvector of the smallest
      eigenvalue of the neighbourhood's covariance (the least-squares plane's normal).
    - Orientation: towards ``viewpoint`` (``n . (viewpoint - p) >= 0``), or, without
      one, outwards from the centroid of the cloud (``n . (p - centroid) >= 0``), which
      is right for star-shaped closed scans. A zero dot product keeps the eigensolver's
      sign.
    - A neighbourhood with no preferred direction (coincident points, a line in 3D)
      gets one of the valid normals, chosen by the eigensolver; never NaN.
    - Scale-free: the centred neighbourhoods are divided by their largest coordinate
      before the covariance, so ``s * points`` has the same normals.
    - The normals are returned without gradient: the eigenvector's derivative is
      unbounded where the two smallest eigenvalues meet, and the orientation is a
      discrete choice.
    - Padded rows (at or past ``lengths``) get zero normals; a cloud with a NaN or inf
      coordinate among its valid points gets NaN normals (its neighbourhoods are
      undefined, as in :func:`knn`).
"""

from __future__ import annotations

import math

import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape
from torchgeo_cg.core.numerics import cast_back
from torchgeo_cg.points._search import check_lengths
from torchgeo_cg.points.nearest_neighbors import knn

__all__ = ["estimate_normals"]


def _pca_normals(p_bnd, idx_bnk):
    """Smallest-eigenvalue eigenvectors ``(B, N, D)`` of the neighbourhoods, in float64."""
    B, N, D = p_bnd.shape
    k = idx_bnk.shape[-1]
    found_bnk = idx_bnk >= 0
    nb = torch.gather(p_bnd, 1, idx_bnk.clamp_min(0).flatten(1)[..., None].expand(-1, -1, D))
    nb_bnkd = nb.reshape(B, N, k, D).double()
    w_bnk1 = found_bnk[..., None].double()
    count = w_bnk1.sum(2, keepdim=True).clamp_min(1)
    mean = (nb_bnkd * w_bnk1).sum(2, keepdim=True) / count
    centred = (nb_bnkd - mean) * w_bnk1
    big = centred.abs().amax(dim=(2, 3), keepdim=True)
    centred = centred / torch.where(big > 0, big, torch.ones_like(big))
    cov_bndd = centred.transpose(-1, -2) @ centred
    cov_bndd = torch.where(torch.isfinite(cov_bndd), cov_bndd, torch.zeros_like(cov_bndd))
    normal = torch.linalg.eigh(cov_bndd).eigenvectors[..., 0]
    return normal, mean[:, :, 0]


def _orient(normal_bnd, p_bnd, valid_bn, viewpoint_bd):
    p = p_bnd.double()
    if viewpoint_bd is None:
        w = valid_bn[..., None].double()
        centre = (torch.where(valid_bn[..., None], p, 0.0)).sum(1, keepdim=True)
        centre = centre / w.sum(1, keepdim=True).clamp_min(1)
        toward = p - centre
    else:
        toward = viewpoint_bd.double()[:, None, :] - p
    flip = (normal_bnd * toward).sum(-1, keepdim=True) < 0
    return torch.where(flip, -normal_bnd, normal_bnd)


def estimate_normals(
    points: torch.Tensor,
    k: int,
    lengths: torch.Tensor | None = None,
    viewpoint: torch.Tensor | None = None,
) -> torch.Tensor:
    """Unit normals of a point cloud by PCA over the ``k`` nearest neighbours.

    Convention:
        See the module docstring: the neighbourhood includes the point; oriented
        towards ``viewpoint`` or outwards from the centroid; no gradient.

    Args:
        points: ``(*, N, D)`` floating point, ``D >= 2`` (the plane of a 3D cloud, the
            line of a 2D one).
        k: neighbours per point, ``>= D`` for a defined plane (``>= 2``).
        lengths: ``(*,)`` integer, valid rows per cloud (default ``N``).
        viewpoint: ``(*, D)`` or ``(D,)``, the sensor position to orient towards.

    Returns:
        ``(*, N, D)`` unit normals, dtype of ``points`` (zero at padded rows).

    Example:
        >>> t = torch.linspace(0, 1, 4)
        >>> plane = torch.stack(torch.meshgrid(t, t, indexing="ij") + (torch.zeros(4, 4),),
        ...                     -1).reshape(-1, 3)
        >>> n = estimate_normals(plane, 6, viewpoint=torch.tensor([0.5, 0.5, -1.0]))
        >>> n[:2]
        tensor([[0., 0., -1.],
                [0., 0., -1.]])
    """
    check_float(points, "points")
    s = check_shape(points, ["*", "N", "D"], "points")
    batch, N, D = s["*"], s["N"], s["D"]
    if D < 2:
        raise ShapeError(f"points: expected shape (*, N, D) with D >= 2, got {tuple(points.shape)}")
    if isinstance(k, bool) or not isinstance(k, int) or k < 2:
        raise ValueError(f"k: expected an int >= 2, got {k!r}")
    len_ = check_lengths(lengths, batch, N, "lengths", points.device)
    B = math.prod(batch)
    vp = None
    if viewpoint is not None:
        check_float(viewpoint, "viewpoint")
        check_shape(viewpoint, ["*", str(D)], "viewpoint")
        if viewpoint.dtype != points.dtype:
            raise TypeError(f"viewpoint: expected dtype {points.dtype} (of points), "
                            f"got {viewpoint.dtype}")
        vp = viewpoint.detach().expand(*batch, D).reshape(B, D)
    with torch.no_grad():
        p = points.detach()
        idx = knn(p, p, k, len_, len_).idx.reshape(B, N, k)
        p_bnd = p.reshape(B, N, D)
        normal, _ = _pca_normals(p_bnd, idx)
        valid_bn = torch.arange(N, device=p.device) < len_.reshape(B, 1)
        normal = _orient(normal, p_bnd, valid_bn, vp)
        bad_bn = ~torch.isfinite(p_bnd).all(-1) & valid_bn  # as knn: the whole cloud
        normal = torch.where(bad_bn.any(-1)[:, None, None], float("nan"), normal)
        normal = torch.where(valid_bn[..., None], normal, 0.0)
    return cast_back(normal, points.dtype).reshape(*batch, N, D)
