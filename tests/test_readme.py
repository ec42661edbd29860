"""The README's API tour runs as written (each ```python block, in a scratch folder)."""

import re
from pathlib import Path

import pytest
import torch

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)


def test_readme_has_a_tour():
    assert len(BLOCKS) >= 5  # transforms, curves, sdf, mesh, estimation


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_block_runs(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # blocks may save meshes or figures
    torch.manual_seed(0)
    namespace: dict = {}
    exec(compile(BLOCKS[index], f"README.md block {index}", "exec"), namespace)
    tensors = {k: v for k, v in namespace.items() if isinstance(v, torch.Tensor)}
    assert tensors, "the block produced no tensor"
    for name, value in tensors.items():  # the tour never shows NaN or inf
        if value.is_floating_point():
            assert torch.isfinite(value).all(), f"README block {index}: {name} is not finite"
