import numpy as np
import pytest
import torch

from torchgeo_cg.core.coerce import as_tensor_like, check_same_dtype


@pytest.mark.parametrize(
    "value",
    [1.5, 2, np.float32(1.5), np.float64(1.5), np.int64(2), np.int32(2), np.array(1.5),
     np.array([1.0, 2.0], dtype=np.float32), [1.0, 2.0], (1, 2)],
)
def test_numbers_and_numpy_follow_the_reference(value, dtype):
    ref = torch.zeros(3, dtype=dtype)
    out = as_tensor_like(value, ref, "x")
    assert out.dtype == dtype and out.device == ref.device
    np.testing.assert_allclose(out.numpy(), np.asarray(value, dtype=np.float64), rtol=1e-7)


def test_without_reference():
    assert as_tensor_like(2, None, "x").dtype == torch.get_default_dtype()
    assert as_tensor_like(np.int64(2), None, "x").dtype == torch.get_default_dtype()
    assert as_tensor_like(np.float64(2), None, "x").dtype == torch.float64
    assert as_tensor_like(np.float32(2), None, "x").dtype == torch.float32
    t = torch.ones(2, dtype=torch.float64)
    assert as_tensor_like(t, None, "x") is t


@pytest.mark.parametrize("value", [True, np.bool_(True), "1.0", None, object(), ["a"],
                                   np.array(["a"]), torch.ones(2, dtype=torch.long),
                                   torch.ones(2, dtype=torch.bool)])
def test_rejections_name_the_argument(value):
    with pytest.raises(TypeError, match="^radius: expected a f"):
        as_tensor_like(value, torch.zeros(2), "radius")


def test_mixed_dtype_names_both_or_casts():
    ref = torch.zeros(2, dtype=torch.float64)
    x = torch.ones(2, dtype=torch.float32, requires_grad=True)
    with pytest.raises(TypeError, match="scale is torch.float32 on cpu but offset is "
                                        "torch.float64 on cpu"):
        as_tensor_like(x, ref, "scale", like_name="offset")
    out = as_tensor_like(x, ref, "scale", cast=True)
    assert out.dtype == torch.float64
    out.sum().backward()
    assert torch.equal(x.grad, torch.ones(2))
    same = torch.ones(2, dtype=torch.float64)
    assert as_tensor_like(same, ref, "scale") is same


def test_check_same_dtype():
    a, b = torch.eye(3), torch.eye(3)
    assert check_same_dtype({"a": a, "b": b}) is a
    with pytest.raises(TypeError, match="c is torch.float64 on cpu but a is torch.float32"):
        check_same_dtype({"a": a, "b": b, "c": b.double()})
