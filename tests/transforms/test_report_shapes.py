"""Tests for torchgeo_cg.transforms.report_shapes, the example and the CLI."""

from __future__ import annotations

import importlib
import math
import runpy
from pathlib import Path

import pytest
import torch

from torchgeo_cg.cli.main import main
from torchgeo_cg.core.testing import assert_close
from torchgeo_cg.transforms import report_shapes, transform_points

ROOT = Path(__file__).resolve().parents[2]
# the package exports the function report_shapes under the module's name: fetch the module
rs = importlib.import_module("torchgeo_cg.transforms.report_shapes")


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


def test_shapes_data(device, dtype):
    shapes = report_shapes(device=device, dtype=dtype)
    assert shapes.start.shape == (10, 2) and shapes.matrices.shape == (8, 3, 3)
    assert shapes.targets.shape == (8, 10, 2)
    assert shapes.start.dtype == dtype and shapes.targets.device.type == device.type
    assert shapes.names == tuple("ABCDEFGH")
    assert_close(shapes.targets, transform_points(shapes.matrices, shapes.start.expand(8, -1, -1)))


def test_matrices_hand_derived():
    m = report_shapes(dtype=torch.float64).matrices
    r = math.sqrt(0.5)
    hand = {
        0: [[1, 0, 5], [0, 1, 1], [0, 0, 1]],
        1: [[1 / 2.45, 0, 7], [0, 1 / 2.45, 0], [0, 0, 1]],
        2: [[1.2, 0, 9.5], [0, 0.4, 1.55], [0, 0, 1]],
        3: [[r, r, 0], [-r, r, 7], [0, 0, 1]],  # R(315°) = R(-45°)
        4: [[0.5 * r, -0.5 * r, 2], [0.5 * r, 0.5 * r, 10], [0, 0, 1]],
        5: [[-0.4 * r, 0.8 * r, 4], [-0.4 * r, -0.8 * r, 14], [0, 0, 1]],
        7: [[0.27, 0, -0.85], [-0.25, -0.2, 5.65], [-0.02, -0.09, 1]],
    }
    for i, want in hand.items():
        assert_close(m[i], torch.tensor(want, dtype=torch.float64), atol=1e-12, rtol=0)
    # G = T(8,8)·R(22.5°)·SH(0.01,1.05)·Ys(0.685)·Xs(0.95), multiplied out by hand
    c, s = math.cos(math.radians(22.5)), math.sin(math.radians(22.5))
    lin = torch.tensor([[c, -s], [s, c]], dtype=torch.float64) @ torch.tensor(
        [[0.95, 0.01 * 0.685], [1.05 * 0.95, 0.685]], dtype=torch.float64)
    assert_close(m[6, :2, :2], lin, atol=1e-12, rtol=0)


def test_start_shape_is_simple_ccw_and_asymmetric():
    start = report_shapes(dtype=torch.float64).start
    x, y = start[:, 0], start[:, 1]
    area = 0.5 * (x * y.roll(-1) - x.roll(-1) * y).sum()
    assert area > 0  # counter-clockwise, non-degenerate
    assert_close(area, torch.tensor(0.6 * 3 + 0.8 * 0.6 + 1.4 * 0.6, dtype=torch.float64))
    # no rotation by a multiple of 90° and no reflection maps the vertex set onto itself
    centered = start - start.mean(0)
    for flip in (1.0, -1.0):
        for k in range(4):
            if flip == 1.0 and k == 0:
                continue
            ang = k * math.pi / 2
            rot = torch.tensor([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]],
                               dtype=torch.float64) @ torch.diag(torch.tensor([flip, 1.0],
                                                                              dtype=torch.float64))
            moved = centered @ rot.T
            dist = torch.cdist(moved, centered).min(dim=1).values
            assert dist.max() > 0.1


def test_fit_report_shapes_recovers_all():
    fit = rs.fit_report_shapes()
    assert fit.error_homography.max() < 1e-6
    assert fit.error_affine[:7].max() < 1e-6
    assert fit.error_affine[7] > 0.1  # H is not affine
    assert (fit.dlt - fit.shapes.matrices).abs().max() < 1e-10


def test_format_transform():
    m = report_shapes(dtype=torch.float64).matrices
    assert rs.format_transform(m[0]) == "T(5,1)"
    assert rs.format_transform(m[1]) == "T(7,0)·S(0.4082)"
    assert rs.format_transform(m[2]) == "T(9.5,1.55)·S(1.2,0.4)"
    assert rs.format_transform(m[4]) == "T(2,10)·R(45°)·S(0.5)"
    assert rs.format_transform(m[7]).startswith("H[[0.27,0,-0.85]")
    assert rs.format_transform(torch.eye(3)) == "I"


def test_table_example_and_cli(capsys, tmp_path):
    table = rs.format_report_table(rs.fit_report_shapes())
    lines = table.splitlines()
    assert len(lines) == 10 and all(line.split(" | ")[0] in "ABCDEFGH" for line in lines[2:])
    assert main(["fit-shapes"]) == 0
    out = capsys.readouterr().out
    assert "T(4,14)·R(-135°)·S(0.4,0.8)" in out and "H[[0.27,0,-0.85]" in out
    assert main(["fit-shapes", "--optimizer", "adam", "--steps", "50"]) == 0
    assert "shape | report (truth)" in capsys.readouterr().out
    pytest.importorskip("matplotlib")
    runpy.run_path(str(ROOT / "examples" / "fit_report_shapes.py"),
                   init_globals={"OUTPUT": tmp_path / "fit.png"}, run_name="__main__")
    assert "shape | report (truth)" in capsys.readouterr().out
    assert (tmp_path / "fit.png").stat().st_size > 1000


# --- contract regressions ----------------------------------------------------------------


@pytest.mark.parametrize("low", [torch.float16, torch.bfloat16])
def test_low_precision_is_built_in_float32_and_cast_back(low):
    """bfloat16 shapes were built in bfloat16 (targets off by 0.06, two roundings per
    product); now the float64 truth rounded once."""
    shapes = report_shapes(dtype=low)
    truth = report_shapes(dtype=torch.float64)
    for got, want in zip(shapes[:3], truth[:3]):
        assert got.dtype == low
        assert_close(got.double(), want.to(low).double(), rtol=torch.finfo(low).eps, atol=0)


def test_fit_in_float16_fits_in_float32_and_casts_back():
    """fit_report_shapes(dtype=float16) raised a raw 'cannot be converted to type c10::Half
    without overflow'; now the float32 fit, cast back."""
    fit = rs.fit_report_shapes(dtype=torch.float16)
    ref = rs.fit_report_shapes(dtype=torch.float32)
    for got, want in zip(fit[1:], ref[1:]):
        assert got.dtype == torch.float16
        assert_close(got.float(), want.to(torch.float16).float(), rtol=0, atol=0)
    assert fit.error_homography.float().max() < 1e-5


def test_integer_dtype_is_rejected_naming_dtype():
    """An integer dtype raised 'offset: expected a floating-point tensor' (an internal
    argument); now the error names dtype."""
    with pytest.raises(TypeError, match="dtype: expected a floating-point"):
        report_shapes(dtype=torch.int64)
    with pytest.raises(TypeError, match="dtype: expected a floating-point"):
        rs.fit_report_shapes(dtype=torch.int32)
