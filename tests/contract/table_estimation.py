"""Contract entries of transforms: estimation, fitting, RANSAC and registration.

``ENTRIES`` join ``table.TABLE``; ``EXEMPT`` names have no geometry (result types,
exceptions, validators).

Correspondences come from a known transform plus small noise: ``src`` is drawn from
a generator seeded by the entry's seed (``g.initial_seed()``), and the ``dst``
generator draws the same ``src`` again, maps it and adds noise, so the two arguments
match although each generator only sees its own shape. Estimated matrices scale by
conjugation (law ``"matrix"``); images have no length (their size is pixels), so the
image laws act on intensities.
"""

from __future__ import annotations

import torch

import torchgeo_cg.transforms as T
from tests.contract.spec import GENERATORS, Arg, Entry

__all__ = ["ENTRIES", "EXEMPT"]

F64 = torch.float64


# ----------------------------------------------------------------------------- generators


def _seeded(g: torch.Generator, offset: int) -> torch.Generator:
    """A generator derived from the entry's seed (the same in every argument's generator)."""
    return torch.Generator().manual_seed(g.initial_seed() * 7 + offset)


def _src(shape, g, dtype):
    """Well-spread source points (*, N, 2), the same for every argument of one seed."""
    return 2 * torch.randn(shape, generator=_seeded(g, 0), dtype=F64)


def _similarity(batch, gen, scale: bool, rotate: bool = True) -> torch.Tensor:
    angle = (2 * torch.rand(batch, generator=gen, dtype=F64) - 1) * (3.0 if rotate else 0.0)
    s = 0.5 + torch.rand(batch, generator=gen, dtype=F64) if scale else torch.ones(batch, dtype=F64)
    t = 3 * torch.randn(*batch, 2, generator=gen, dtype=F64)
    m = torch.zeros(*batch, 3, 3, dtype=F64)
    m[..., 0, 0], m[..., 0, 1] = s * angle.cos(), -s * angle.sin()
    m[..., 1, 0], m[..., 1, 1] = s * angle.sin(), s * angle.cos()
    m[..., :2, 2], m[..., 2, 2] = t, 1.0
    return m


def _matrix_of(kind: str, batch, gen) -> torch.Tensor:
    if kind in ("homography", "affine"):
        return GENERATORS[kind]((*batch, 3, 3), gen, F64)
    if kind == "translation":
        return _similarity(batch, gen, scale=False, rotate=False)
    return _similarity(batch, gen, scale=kind == "similarity")


def _dst(kind: str, noise: float = 1e-2, outliers: int = 0):
    """``dst`` generator: a ``kind`` transform of :func:`_src` plus noise (and outliers)."""

    def gen(shape, g, dtype):
        src = _src(shape, g, dtype)
        sub = _seeded(g, 1)
        m = _matrix_of(kind, shape[:-2], sub)
        dst = T.transform_points(m, src) + noise * torch.randn(shape, generator=sub, dtype=F64)
        if outliers:
            dst[..., -outliers:, :] = 6 * torch.randn(*shape[:-2], outliers, 2, generator=sub,
                                                      dtype=F64)
        return dst

    return gen


def _weights(shape, g, dtype):
    return 0.5 + torch.rand(shape, generator=g, dtype=F64)


def _small(shape, g, dtype):
    """Small parameters (corner offsets, sl3 coordinates): a mild, regular homography."""
    return 0.2 * torch.randn(shape, generator=g, dtype=F64)


def _pixel_matrix(shape, g, dtype):
    """``input_from_output`` pixel warps near the identity (a pixel of shift, mild perspective)."""
    m = torch.eye(3, dtype=F64).expand(*shape).clone()
    m[..., :2, :2] += 0.05 * torch.randn(*shape[:-2], 2, 2, generator=g, dtype=F64)
    m[..., :2, 2] = torch.randn(*shape[:-2], 2, generator=g, dtype=F64)
    m[..., 2, :2] = 2e-3 * torch.randn(*shape[:-2], 2, generator=g, dtype=F64)
    return m


def _blobs(shape, gen) -> torch.Tensor:
    """Smooth images (B, C, H, W): a sum of three Gaussian blobs with random centres."""
    *lead, h, w = shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=F64), torch.arange(w, dtype=F64),
                            indexing="ij")
    out = torch.zeros(shape, dtype=F64)
    for _ in range(3):  # three fixed blobs, not a loop over data
        cx = (0.25 + 0.5 * torch.rand(*lead, 1, 1, generator=gen, dtype=F64)) * (w - 1)
        cy = (0.25 + 0.5 * torch.rand(*lead, 1, 1, generator=gen, dtype=F64)) * (h - 1)
        out = out + torch.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (0.05 * h * w))
    return out


def _source_image(shape, g, dtype):
    return _blobs(shape, _seeded(g, 2))


def _target_image(shape, g, dtype):
    """The source image moved by a known sub-pixel translation (``target_from_source``)."""
    src = _blobs(shape, _seeded(g, 2))
    shift = torch.eye(3, dtype=F64).repeat(shape[0], 1, 1)
    shift[:, :2, 2] = 0.6 * (2 * torch.rand(shape[0], 2, generator=_seeded(g, 3),
                                            dtype=F64) - 1)
    return T.warp_image(src, torch.linalg.inv(shift)).image


def _trs_matrix(shape, g, dtype):
    p = torch.randn(*shape[:-2], 5, generator=g, dtype=F64) * torch.tensor(
        [3.0, 3.0, 1.0, 0.3, 0.3], dtype=F64)
    return T.parameters_to_matrix(p, "trs")


# ----------------------------------------------------------------------------- calls


def _ransac(model: str):
    def call(src, dst):
        # the threshold is a length: a fraction of the data's extent (scales with it)
        top = float(dst.detach().abs().amax()) if dst.numel() else 1.0
        fit = T.find_transform_ransac(src, dst, model, threshold=0.05 * top,
                                      generator=torch.Generator().manual_seed(0),
                                      hypotheses_per_round=16)
        return tuple(fit)

    return call


def _ransac_weighted(weights, src, dst):
    top = float(dst.detach().abs().amax()) if dst.numel() else 1.0
    return tuple(T.find_transform_ransac(src, dst, "affine", threshold=0.05 * top,
                                         weights=weights,
                                         generator=torch.Generator().manual_seed(0),
                                         hypotheses_per_round=16))


def _fit_robust(src, dst):
    # the robust scale is a length: a fraction of the data's extent (scales with it). A
    # robust loss needs a good start (documented): the DLT's
    top = float(dst.detach().abs().amax()) if dst.numel() else 1.0
    init = T.find_homography_dlt(src, dst).matrix
    return tuple(T.fit_transform(src, dst, "homography", init=init,
                                 solver=T.SolverOptions("lm", steps=3, tol=0.0),
                                 loss=T.LossOptions("huber", scale=0.1 * top)))


def _split_params(model: str):
    """matrix_to_parameters split into (unitless, length) parts where the model mixes them."""
    length = {"affine": [2, 5], "similarity": [2, 3], "euclidean": [1, 2], "trs": [0, 1]}[model]

    def call(m):
        p = T.matrix_to_parameters(m, model)
        rest = [i for i in range(p.shape[-1]) if i not in length]
        return p[..., rest], p[..., length]

    return call


# ----------------------------------------------------------------------------- entries

N = 8
SRC = Arg("src", (2, N, 2), _src)
BADP = ((2, N, 4), (2,))  # (2, N, 3) is a valid 3D problem for some
PAIR_EMPTY = ((0, 0), (1, 0))  # N = 0 is a ShapeError (a fit of no points is undefined)
MAT = Arg("matrix", (4, 3, 3), "homography", "matrix")
BADM = ((4, 3, 2), (3,))
RANSAC_N = 24


def _closed_form(name: str, kind: str) -> list[Entry]:
    fn = getattr(T, name)
    return [
        Entry(f"transforms.{name}", lambda s, d: tuple(fn(s, d)),
              (SRC, Arg("dst", (2, N, 2), _dst(kind))), out=("matrix", "index", "unitless"),
              empty=PAIR_EMPTY, bad=((2, N, 4), (2,))),
        # weights first: NaN weights give NaN, integer weights are rejected
        Entry(f"transforms.{name}[weights]", lambda w, s, d: tuple(fn(s, d, w)),
              (Arg("weights", (2, N), _weights, "unitless"), SRC,
               Arg("dst", (2, N, 2), _dst(kind))),
              out=("matrix", "index", "unitless"), empty=((0, 0), (1, 0), (2, 0)),
              bad=((2, N + 1), (2, N, 2))),
    ]


ENTRIES: list[Entry] = [
    *_closed_form("find_affine", "affine"),
    *_closed_form("find_similarity", "similarity"),
    *_closed_form("find_euclidean", "euclidean"),
    *_closed_form("find_translation", "translation"),
    Entry("transforms.find_homography_dlt", lambda s, d: tuple(T.find_homography_dlt(s, d)),
          (SRC, Arg("dst", (2, N, 2), _dst("homography"))),
          out=("matrix", "index", "unitless"), empty=PAIR_EMPTY, bad=BADP),
    Entry("transforms.find_homography_dlt[weights]",
          lambda w, s, d: tuple(T.find_homography_dlt(s, d, w)),
          (Arg("weights", (2, N), _weights, "unitless"), SRC,
           Arg("dst", (2, N, 2), _dst("homography"))),
          out=("matrix", "index", "unitless"), empty=((0, 0), (1, 0), (2, 0)),
          bad=((2, N + 1), (2, N, 2))),
    # transform = [[s, 0, -s cx], [0, s, -s cy], [0, 0, 1]]: its first two columns scale
    # like 1 / length, its last column is unitless
    Entry("transforms.hartley_normalize",
          lambda p: (lambda o: (o.points, o.transform[..., :2], o.transform[..., 2], o.centroid,
                                o.scale))(T.hartley_normalize(p)),
          (Arg("points", (2, N, 2)),),
          out=("unitless", "inv_length", "unitless", "length", "inv_length"),
          empty=(0, 0), bad=((2, N, 3), (2,))),
    Entry("transforms.hartley_normalize[weights]",
          lambda w, p: (lambda o: (o.points, o.transform[..., :2], o.transform[..., 2],
                                   o.centroid, o.scale))(T.hartley_normalize(p, w)),
          (Arg("weights", (2, N), _weights, "unitless"), Arg("points", (2, N, 2))),
          out=("unitless", "inv_length", "unitless", "length", "inv_length"),
          empty=((0, 0), (1, 0)), bad=((2, N + 1), (2, N, 2)),
          mixed=("follow", 1)),  # weights follow the points (documented)
    Entry("transforms.reprojection_error", lambda s, d, m: T.reprojection_error(m, s, d),
          (SRC, Arg("dst", (2, N, 2), _dst("homography")),
           Arg("matrix", (2, 3, 3), "homography", "matrix")),
          out="area", empty=((0, 0), (1, 0), (2, 0)), bad=BADP),
    Entry("transforms.reprojection_error[symmetric]",
          lambda s, d, m: T.reprojection_error(m, s, d, symmetric=True),
          (SRC, Arg("dst", (2, N, 2), _dst("homography")),
           Arg("matrix", (2, 3, 3), "homography", "matrix")),
          out="area", empty=((0, 0), (1, 0), (2, 0)), bad=BADP),
    Entry("transforms.reprojection_error[weights]",
          lambda w, s, d, m: T.reprojection_error(m, s, d, w),
          (Arg("weights", (2, N), _weights, "unitless"), SRC,
           Arg("dst", (2, N, 2), _dst("homography")),
           Arg("matrix", (2, 3, 3), "homography", "matrix")),
          out="area", empty=((0, 0), (1, 0), (2, 0), (3, 0)), bad=((2, N + 1), (2, N, 2))),
    # --- parameters <-> matrices
    Entry("transforms.matrix_to_parameters", T.matrix_to_parameters, (MAT,), out="h8",
          empty=(0, 0), bad=BADM),
    # the corner and sl3 parameters live in the fixed normalized frame: a matrix and any
    # multiple of it (the same projective map) give the same parameters
    Entry("transforms.matrix_to_parameters[corners]",
          lambda m: T.matrix_to_parameters(m, "homography", "corners"),
          (Arg("matrix", (4, 3, 3), "homography", "length"),), out="unitless", empty=(0, 0),
          bad=BADM),
    Entry("transforms.matrix_to_parameters[sl3]",
          lambda m: T.matrix_to_parameters(m, "homography", "sl3"),
          (Arg("matrix", (4, 3, 3), "homography", "length"),), out="unitless", empty=(0, 0),
          bad=BADM),
    Entry("transforms.matrix_to_parameters[affine]", _split_params("affine"),
          (Arg("matrix", (4, 3, 3), "affine", "matrix"),), out=("unitless", "length"),
          empty=(0, 0), bad=BADM),
    Entry("transforms.matrix_to_parameters[similarity]", _split_params("similarity"),
          (Arg("matrix", (4, 3, 3), "affine", "matrix"),), out=("unitless", "length"),
          empty=(0, 0), bad=BADM),
    Entry("transforms.matrix_to_parameters[euclidean]", _split_params("euclidean"),
          (Arg("matrix", (4, 3, 3), "affine", "matrix"),), out=("unitless", "length"),
          empty=(0, 0), bad=BADM),
    Entry("transforms.matrix_to_parameters[translation]",
          lambda m: T.matrix_to_parameters(m, "translation"),
          (Arg("matrix", (4, 3, 3), "affine", "matrix"),), out="length", empty=(0, 0),
          bad=BADM),
    Entry("transforms.matrix_to_parameters[trs]", _split_params("trs"),
          (Arg("matrix", (4, 3, 3), _trs_matrix, "matrix"),), out=("unitless", "length"),
          empty=(0, 0), bad=BADM),
    Entry("transforms.parameters_to_matrix", T.parameters_to_matrix,
          (Arg("params", (4, 8), "normal", "h8"),), out="matrix", empty=(0, 0),
          bad=((4, 9), ())),
    Entry("transforms.parameters_to_matrix[translation]",
          lambda p: T.parameters_to_matrix(p, "translation"), (Arg("params", (4, 2)),),
          out="matrix", empty=(0, 0), bad=((4, 3), ())),
    # the other models mix lengths and unitless values in one params vector (no law
    # for that); they are parameters of the unitless Hartley frame
    *[Entry(f"transforms.parameters_to_matrix[{model}]",
            lambda p, model=model: T.parameters_to_matrix(p, model),
            (Arg("params", (4, size), "normal", "unitless"),), out="unitless", empty=(0, 0),
            bad=((4, size + 1), ()))
      for model, size in (("affine", 6), ("similarity", 4), ("euclidean", 3), ("trs", 5))],
    Entry("transforms.parameters_to_matrix[corners]",
          lambda p: T.parameters_to_matrix(p, "homography", "corners"),
          (Arg("params", (4, 8), _small, "unitless"),), out="unitless", empty=(0, 0),
          bad=((4, 9), ())),
    # base @ exp(G): linear in the base
    Entry("transforms.parameters_to_matrix[sl3]",
          lambda p, b: T.parameters_to_matrix(p, "homography", "sl3", b),
          (Arg("params", (4, 8), _small, "unitless"),
           Arg("base", (4, 3, 3), "homography", "length")),
          out="length", empty=((0, 0), (1, 0)), bad=((4, 9), ())),
    # --- iterative fits (few steps). LM runs with tol=0: every step is taken, so the
    # history has one length at every scale (in float32 the convergence test flips at
    # rounding: 4 vs 5 entries at seed 1109); early stopping is tested in test_fitting.py.
    # float32 homography LM (steps solved from JᵀJ, which squares the condition): measured
    # worst 1.1e-4 (entries, 40 seeds), 1.4e-4 (sl3, 40; corners, 30) -> rtol32 = 5
    Entry("transforms.fit_transform",
          lambda s, d: tuple(T.fit_transform(s, d, "homography",
                                             solver=T.SolverOptions("lm", steps=4, tol=0.0))),
          (SRC, Arg("dst", (2, N, 2), _dst("homography"))),
          out=("matrix", "unitless", "area", "area"), empty=PAIR_EMPTY, bad=BADP, rtol32=5.0),
    Entry("transforms.fit_transform[similarity]",
          lambda s, d: tuple(T.fit_transform(s, d, "similarity",
                                             solver=T.SolverOptions("lm", steps=4, tol=0.0))),
          (SRC, Arg("dst", (2, N, 2), _dst("similarity"))),
          out=("matrix", "unitless", "area", "area"), empty=PAIR_EMPTY, bad=BADP),
    Entry("transforms.fit_transform[weights]",
          lambda w, s, d: tuple(T.fit_transform(s, d, "affine", weights=w,
                                                solver=T.SolverOptions("lm", steps=3, tol=0.0))),
          (Arg("weights", (2, N), _weights, "unitless"), SRC,
           Arg("dst", (2, N, 2), _dst("affine"))),
          out=("matrix", "unitless", "area", "area"), empty=((0, 0), (1, 0), (2, 0)),
          bad=((2, N + 1), (2, N, 2))),
    # torch's L-BFGS strong-Wolfe line search decides on float32 cost comparisons at
    # rounding level: typically 5e-4 (24 seeds), worst seen 1.7e-2 (the loss, one CI seed);
    # float64 1e-12
    Entry("transforms.fit_transform[lbfgs]",
          lambda s, d: tuple(T.fit_transform(s, d, "euclidean",
                                             solver=T.SolverOptions("lbfgs", steps=3))),
          (SRC, Arg("dst", (2, N, 2), _dst("euclidean"))),
          out=("matrix", "unitless", "area", "area"), empty=PAIR_EMPTY, bad=BADP, rtol32=300.0),
    # Adam from a start away from the optimum: a parameter at its optimum (zero gradient)
    # would be kicked by the sign of rounding noise (Adam's steps are about lr whatever |g|)
    Entry("transforms.fit_transform[adam]",
          lambda s, d, init: tuple(T.fit_transform(s, d, "trs", init=init,
                                                   solver=T.SolverOptions("adam", steps=3))),
          (SRC, Arg("dst", (2, N, 2), _dst("similarity")),
           Arg("init", (2, 3, 3), _trs_matrix, "matrix")),
          out=("matrix", "unitless", "area", "area"), empty=((0, 0), (1, 0), (2, 0)), bad=BADP),
    Entry("transforms.fit_transform[sl3]",
          lambda s, d: tuple(T.fit_transform(s, d, "homography", parametrization="sl3",
                                             solver=T.SolverOptions("lm", steps=3, tol=0.0),
                                             loss=T.LossOptions(symmetric=True))),
          (SRC, Arg("dst", (2, N, 2), _dst("homography"))),
          out=("matrix", "unitless", "area", "area"), empty=PAIR_EMPTY, bad=BADP, rtol32=5.0),
    Entry("transforms.fit_transform[corners]",
          lambda s, d: tuple(T.fit_transform(s, d, "homography", parametrization="corners",
                                             solver=T.SolverOptions("lm", steps=3, tol=0.0))),
          (SRC, Arg("dst", (2, N, 2), _dst("homography"))),
          out=("matrix", "unitless", "area", "area"), empty=PAIR_EMPTY, bad=BADP, rtol32=5.0),
    Entry("transforms.fit_transform[huber]", _fit_robust,
          (Arg("src", (2, 16, 2), _src), Arg("dst", (2, 16, 2), _dst("homography", outliers=2))),
          out=("matrix", "unitless", "area", "area"), empty=PAIR_EMPTY, bad=BADP),
    Entry("transforms.HomographyModel",
          lambda p, init, s, d: T.HomographyModel(batch_shape=tuple(s.shape[:-2]), src=s, dst=d,
                                                  init=init)(p),
          (Arg("points", (2, 5, 2)), Arg("init", (2, 3, 3), "homography", "matrix"), SRC,
           Arg("dst", (2, N, 2), _dst("homography"))),
          bad=((2, 5, 3), (2,))),
    # --- RANSAC: a seeded generator in the call, so every scale draws the same samples.
    # NaN points are outliers (never sampled, never inliers): "skip"; NaN weights give a
    # NaN matrix ([weights])
    # the homography ends with LM, which accepts a step only where the cost drops: the
    # optimum is resolved to ~sqrt(eps) x its conditioning. Measured worst 5.3e-9 (30 seeds)
    Entry("transforms.find_transform_ransac", _ransac("homography"),
          (Arg("src", (2, RANSAC_N, 2), _src),
           Arg("dst", (2, RANSAC_N, 2), _dst("homography", outliers=6))),
          out=("matrix", "index", "index", "index"), empty=PAIR_EMPTY, nan="skip",
          bad=((2, RANSAC_N, 4), (2,)), rtol=1e-7),
    Entry("transforms.find_transform_ransac[similarity]", _ransac("similarity"),
          (Arg("src", (2, RANSAC_N, 2), _src),
           Arg("dst", (2, RANSAC_N, 2), _dst("similarity", outliers=6))),
          out=("matrix", "index", "index", "index"), empty=PAIR_EMPTY, nan="skip",
          bad=((2, RANSAC_N, 4), (2,))),
    Entry("transforms.find_transform_ransac[weights]", _ransac_weighted,
          (Arg("weights", (2, RANSAC_N), _weights, "unitless"),
           Arg("src", (2, RANSAC_N, 2), _src),
           Arg("dst", (2, RANSAC_N, 2), _dst("affine", outliers=6))),
          out=("matrix", "index", "index", "index"), empty=((0, 0), (1, 0), (2, 0)),
          bad=((2, RANSAC_N + 1), (2, RANSAC_N, 2))),
    # --- images: sizes are pixels (no scale); the laws act on intensities.
    # warp_image is linear in the intensities
    Entry("transforms.warp_image", lambda img, m: tuple(T.warp_image(img, m)),
          (Arg("image", (2, 1, 6, 7)), Arg("matrix", (2, 3, 3), _pixel_matrix, "unitless")),
          out=("length", "index"), empty=((0, 0), (1, 0)), bad=((2, 6, 7), (2, 1, 7))),
    # a matrix and any positive multiple of it are the same warp
    Entry("transforms.warp_image[projective]", lambda img, m: tuple(T.warp_image(img, m)),
          (Arg("image", (2, 1, 6, 7), "normal", "unitless"),
           Arg("matrix", (2, 3, 3), _pixel_matrix, "length")),
          out=("unitless", "index"), empty=((0, 0), (1, 0)), bad=((2, 6, 7), (2, 1, 7))),
    # ssd: both images scaled by s scale the loss by s^2 and leave the matrix as it is
    Entry("transforms.register_images",
          lambda s, t: tuple(T.register_images(s, t, "translation", levels=1, iterations=3)),
          (Arg("source", (2, 1, 12, 12), _source_image),
           Arg("target", (2, 1, 12, 12), _target_image)),
          out=("unitless", "area", "area", "index"), empty=((0, 0), (1, 0)),
          bad=((2, 12, 12), (2, 1, 12))),
    Entry("transforms.register_images[adam]",
          lambda s, t: tuple(T.register_images(s, t, "similarity", levels=1, iterations=3,
                                               optimizer="adam", lr=1e-2)),
          (Arg("source", (2, 1, 12, 12), _source_image),
           Arg("target", (2, 1, 12, 12), _target_image)),
          out=("unitless", "area", "area", "index"), empty=((0, 0), (1, 0)),
          bad=((2, 12, 12), (2, 1, 12))),
    # ncc: invariant to the target's contrast (a gain is fitted at every step)
    Entry("transforms.register_images[ncc]",
          lambda s, t: tuple(T.register_images(s, t, "affine", levels=2, iterations=2,
                                               loss="ncc")),
          (Arg("source", (2, 1, 16, 16), _source_image, "unitless"),
           Arg("target", (2, 1, 16, 16), _target_image)),
          out=("unitless", "unitless", "unitless", "index"), empty=((0, 0), (1, 0)),
          bad=((2, 16, 16), (2, 1, 16))),
]

EXEMPT: dict[str, str] = {
    "transforms.FitResult": "NamedTuple result of fit_transform (no geometry of its own)",
    "transforms.SolverOptions": "option bundle of fit_transform (frozen dataclass, validated "
                                "when built; tests/transforms/test_fitting.py)",
    "transforms.LossOptions": "option bundle of fit_transform (frozen dataclass, validated "
                              "when built; tests/transforms/test_fitting.py)",
    "transforms.HartleyNormalization": "NamedTuple result of hartley_normalize",
    "transforms.RobustFit": "NamedTuple result of find_transform_ransac",
    "transforms.RegistrationResult": "NamedTuple result of register_images",
    "transforms.WarpedImage": "NamedTuple result of warp_image",
}

