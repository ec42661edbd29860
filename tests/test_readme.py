"""The README's API tour runs as written (each ```python block, in a scratch folder)."""

import re
from pathlib import Path

import pytest
import torch

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)


def test_readme_has_a_tour():
    assert len(BLOCKS) >= 5  # transforms, curves, sdf, mesh, estimation


@pytest.mark.slow  # the SDF and estimation blocks take 10-40 s on a shared 2-core machine
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


def _commands() -> list[str]:
    """The README's set-up commands (```bash blocks), one line each."""
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", README.read_text(), re.S)]


def test_ci_runs_the_readme_test_command_verbatim():
    commands = _commands()
    assert len(commands) == 2 and commands[1].endswith("&& pytest")
    ci = (README.parent / ".ci" / "run").read_text()
    assert commands[1] in ci.splitlines()
    assert "ruff check ." in ci.splitlines()


def test_readme_renders_on_its_own():
    """The wheel's long description links nothing outside the package (no ../, no repo paths)."""
    text = README.read_text()
    assert "../" not in text
    links = re.findall(r"\]\(([^)]+)\)", text)
    assert all(link.startswith(("http://", "https://", "#")) for link in links), links
