import pytest
import torch

from torchgeo_cg.core.check import ShapeError, check_float, check_shape, check_tensor


def test_check_shape_binds_named_sizes_and_batch():
    sizes = check_shape(torch.zeros(2, 3, 7, 2), ["*", "N", "2"], "points")
    assert sizes == {"*": (2, 3), "N": 7}
    # the bound sizes carry over to the next check
    check_shape(torch.zeros(7), ["N"], "weights", sizes)
    with pytest.raises(
        ShapeError, match=r"weights: expected shape \(N\), got \(6\) \(N=6 but N=7 elsewhere\)"
    ):
        check_shape(torch.zeros(6), ["N"], "weights", sizes)


def test_star_matches_no_batch_dims():
    assert check_shape(torch.zeros(5, 2), ["*", "N", "2"], "points") == {"N": 5, "*": ()}


@pytest.mark.parametrize(
    "shape, pattern, message",
    [
        ((5, 3), ["*", "N", "2"], "matrix: expected shape (*, N, 2), got (5, 3)"),
        ((2,), ["*", "N", "2"], "matrix: expected shape (*, N, 2), got (2)"),
        ((4, 3, 3), ["3", "3"], "matrix: expected shape (3, 3), got (4, 3, 3)"),
        ((3, 4), ["N", "N"], "matrix: expected shape (N, N), got (3, 4) (N=4 but N=3 elsewhere)"),
    ],
)
def test_check_shape_errors_name_argument_expected_and_got(shape, pattern, message):
    with pytest.raises(ShapeError) as err:
        check_shape(torch.zeros(shape), pattern, "matrix")
    assert str(err.value) == message
    assert isinstance(err.value, ValueError)


def test_star_only_first():
    with pytest.raises(ValueError, match="only be the first"):
        check_shape(torch.zeros(2, 2), ["N", "*"], "x")


def test_check_tensor_and_float():
    with pytest.raises(TypeError, match="points: expected a torch.Tensor, got ndarray"):
        import numpy as np

        check_tensor(np.zeros(3), "points")
    with pytest.raises(
        TypeError, match="offset: expected a floating-point tensor, got dtype torch.int32"
    ):
        check_float(torch.zeros(2, dtype=torch.int32), "offset")
    x = torch.zeros(2, dtype=torch.float64)
    assert check_float(x, "x") is x


def test_library_has_no_assert_statements():
    """Input checks must survive ``python -O``: no ``assert`` anywhere in the package."""
    import ast
    import pathlib

    import torchgeo_cg

    root = pathlib.Path(torchgeo_cg.__file__).parent
    offenders = []
    for path in root.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        offenders += [
            f"{path.name}:{n.lineno}" for n in ast.walk(tree) if isinstance(n, ast.Assert)
        ]
    assert offenders == []


def test_check_choice_names_the_argument_and_every_accepted_value():
    from torchgeo_cg.core.check import check_choice

    assert check_choice("sum", ("mean", "sum"), "reduction") == "sum"
    with pytest.raises(ValueError, match=r"^reduction: expected one of 'mean', 'sum', got 'avg'$"):
        check_choice("avg", ("mean", "sum"), "reduction")
    with pytest.raises(ValueError, match=r"model: expected one of 'a', 'b', got \['a'\]"):
        check_choice(["a"], {"b", "a"}, "model")  # unhashable value, sorted set
    assert check_choice("x", {"x": 1}, "key") == "x"


def test_check_generator_names_the_argument_type_and_device():
    from torchgeo_cg.core.check import check_generator

    g = torch.Generator()
    assert check_generator(g) is g
    with pytest.raises(TypeError, match=r"^gen: expected a torch.Generator, got int$"):
        check_generator(3, "gen")
    with pytest.raises(ValueError, match=r"^generator: expected a generator on cuda, got one"):
        check_generator(g, device="cuda")
