"""records_graph: every case of "does autograd record this call", and the rule that no
private torch function is called outside it."""

from __future__ import annotations

import ast
from pathlib import Path

import torch
import torch.autograd.forward_ad as fwAD

import torchgeo_cg
from torchgeo_cg.core import hypot, records_graph
from torchgeo_cg.transforms import transform_points

F64 = torch.float64


def test_reverse_mode_needs_grad_mode_and_a_tensor_that_requires_grad():
    x = torch.ones(3, requires_grad=True)
    y = torch.ones(3)
    assert records_graph(x) and records_graph(y, x) and records_graph(None, x)
    assert not records_graph(y) and not records_graph(x.detach()) and not records_graph()
    assert not records_graph(None, y)
    with torch.no_grad():
        assert not records_graph(x)
    with torch.inference_mode():
        assert not records_graph(x)
    with torch.enable_grad():
        assert records_graph(x)


def test_forward_mode_dual_tensors_record_with_or_without_grad_mode():
    x = torch.ones(3)
    with fwAD.dual_level():
        dual = fwAD.make_dual(x, torch.ones(3))
        assert records_graph(dual) and records_graph(x, dual)
        assert not records_graph(x)
        with torch.no_grad():
            assert records_graph(dual)  # forward mode ignores grad mode
    assert not records_graph(x)


def test_functorch_transforms_always_record():
    seen = []

    def probe(t):
        seen.append(records_graph(t))
        seen.append(records_graph())  # no tensor: a transform alone answers
        return t * 2

    torch.func.vmap(probe)(torch.ones(2, 3))
    torch.func.grad(lambda t: probe(t).sum())(torch.ones(3))
    torch.func.jvp(probe, (torch.ones(3),), (torch.ones(3),))
    assert seen == [True] * 6
    assert not records_graph()  # outside every transform


def test_sites_follow_forward_mode():
    # a fast path that skipped the graph would lose the tangent; the sites now see it
    x, y, tx = (torch.randn(7, generator=torch.Generator().manual_seed(i), dtype=F64)
                for i in range(3))
    with fwAD.dual_level():
        r = hypot(fwAD.make_dual(x, tx), y)
        torch.testing.assert_close(fwAD.unpack_dual(r).tangent, x * tx / torch.hypot(x, y))
    m = torch.eye(3, dtype=F64)
    p = torch.randn(5, 2, generator=torch.Generator().manual_seed(4), dtype=F64)
    tm = torch.zeros(3, 3, dtype=F64)
    tm[0, 2] = 1.0  # moving the x translation moves every point by (1, 0)
    out, tangent = torch.func.jvp(lambda a: transform_points(a, p), (m,), (tm,))
    torch.testing.assert_close(out, p)
    torch.testing.assert_close(tangent, torch.tensor([1.0, 0.0], dtype=F64).expand(5, 2))


def test_hypot_gradcheck_forward_and_reverse():
    x = torch.randn(6, dtype=F64, requires_grad=True)
    y = torch.randn(6, dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(hypot, (x, y), check_forward_ad=True)


def _private_torch_calls(tree: ast.AST) -> list[str]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            text = ast.unparse(node)
            if text.startswith(("torch._C", "torch._functorch")) or (
                    text.startswith("torch.") and ".is_grad_enabled" in text):
                found.append(text)
    return found


def test_no_private_torch_query_outside_records_graph():
    root = Path(torchgeo_cg.__file__).parent
    offenders = {}
    for path in sorted(root.rglob("*.py")):
        if path == root / "core" / "autograd.py":
            continue
        found = _private_torch_calls(ast.parse(path.read_text()))
        if found:
            offenders[str(path.relative_to(root))] = found
    assert offenders == {}, offenders


def test_is_transform_wrapped_inside_and_outside_torch_func():
    from torchgeo_cg.core import is_transform_wrapped

    x = torch.randn(2, 3)
    assert not is_transform_wrapped(x)
    seen = []
    torch.func.vmap(lambda r: seen.append(is_transform_wrapped(r)) or r)(x)
    torch.func.grad(lambda r: seen.append(is_transform_wrapped(r)) or r.sum())(x)
    assert seen == [True, True]
