"""The README is a short front door: at most 200 lines, the two set-up commands (the test
one is what ``.ci/run`` runs, verbatim), links that lead somewhere, and no reference to an
equation of a document the reader does not have. Its example runs in
``tests/test_guides.py``, with the guides' tours."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _commands() -> list[str]:
    """The README's set-up commands (```bash blocks), one line each."""
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", README.read_text(), re.S)]


def test_readme_is_short():
    assert len(README.read_text().splitlines()) <= 200


def test_ci_runs_the_readme_test_command_verbatim():
    commands = _commands()
    assert len(commands) == 2 and commands[1].endswith("&& pytest")
    assert commands[0].endswith("torchgeo-cg gallery")
    ci = (ROOT / ".ci" / "run").read_text()
    assert commands[1] in ci.splitlines()
    assert "ruff check ." in ci.splitlines()


def test_readme_links_lead_somewhere():
    """Relative links (guides, conventions, the picture) name files of the repository."""
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README.read_text())
    assert links
    for link in links:
        if not link.startswith(("http://", "https://")):
            assert (ROOT / link).is_file(), link


def test_no_report_equation_numbers():
    """'report eq. 3' points at a document the reader does not have: give the equation."""
    pattern = re.compile(r"report[^.\n]{0,40}\beqs?\.\s*\d|\(eqs?\.\s*\d+\)", re.I)
    files = [README, *(ROOT / "docs").rglob("*.md"), *(ROOT / "torchgeo_cg").rglob("*.py")]
    found = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in files
             if "_generated" not in p.parts
             for m in pattern.finditer(p.read_text(encoding="utf-8"))]
    assert found == []
