"""The guides run as written: every ```python block of every ``docs/guide/*.md``, in order,
in one namespace per page (a scratch folder as the working directory), and the README's
example. A new guide page is picked up by the glob."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
GUIDES = sorted((ROOT / "docs" / "guide").glob("*.md"))
FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks(path: Path) -> list[str]:
    """The ```python blocks of a Markdown file, in order."""
    return FENCE.findall(path.read_text(encoding="utf-8"))


def run_blocks(path: Path) -> dict:
    """Execute a page's blocks in one namespace; returns the namespace."""
    torch.manual_seed(0)
    namespace: dict = {"__name__": f"guide_{path.stem}"}
    for index, block in enumerate(python_blocks(path)):
        exec(compile(block, f"{path.name} block {index}", "exec"), namespace)
    return namespace


def _check_finite(namespace: dict, where: str) -> None:
    tensors = {k: v for k, v in namespace.items() if isinstance(v, torch.Tensor)}
    assert tensors, f"{where}: the blocks produced no tensor"
    for name, value in tensors.items():  # a tour never shows NaN or inf
        if value.is_floating_point():
            assert torch.isfinite(value).all(), f"{where}: {name} is not finite"


def test_every_area_has_a_guide_with_blocks():
    names = {p.stem for p in GUIDES}
    assert {"transforms", "estimation", "curves", "surfaces", "sdf", "marching_cubes",
            "subdivision", "points"} <= names
    for path in GUIDES:
        assert python_blocks(path), f"{path.name} has no ```python block"


def test_block_extraction_keeps_order_and_skips_other_languages(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("```bash\necho no\n```\n```python\nx = 1\n```\ntext\n```python\ny = x\n```\n")
    assert python_blocks(page) == ["x = 1\n", "y = x\n"]


@pytest.mark.parametrize("path", GUIDES, ids=[p.stem for p in GUIDES])
def test_guide_runs(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # blocks may save meshes or figures
    _check_finite(run_blocks(path), path.name)


def test_readme_example_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    blocks = python_blocks(ROOT / "README.md")
    assert len(blocks) == 1, "the README has one example"
    namespace: dict = {}
    exec(compile(blocks[0], "README.md example", "exec"), namespace)
    _check_finite(namespace, "README.md")
