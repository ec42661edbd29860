"""Build the gallery: render every registered figure and write ``index.html``."""

from __future__ import annotations

import html
import importlib
import os
import pkgutil
from pathlib import Path

from torchgeo_cg.viz.registry import GalleryFigure, registered_figures

__all__ = ["build_gallery", "check_output_folder", "check_sections", "load_figure_modules"]

_SKIP = {"registry"}  # the registry itself; private helpers start with "_"


def load_figure_modules() -> list[str]:
    """Import every figure module of :mod:`torchgeo_cg.viz` (needs matplotlib)."""
    names = []
    for info in pkgutil.iter_modules([str(Path(__file__).parent)]):
        if info.name in _SKIP or info.name.startswith("_"):
            continue
        importlib.import_module(f"torchgeo_cg.viz.{info.name}")
        names.append(info.name)
    return names


def check_output_folder(out_dir: str | Path) -> Path:
    """The gallery's output folder, created if missing; it must be writable.

    Raises:
        ValueError: ``out_dir`` is empty (it would mean the current folder).
        OSError: it is a file, lies under a file, or cannot be created or written
            (``FileExistsError``, ``NotADirectoryError``, ``PermissionError``).

    Example:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as tmp:
        ...     check_output_folder(Path(tmp) / "a" / "b").is_dir()
        True
        >>> check_output_folder("")
        Traceback (most recent call last):
        ...
        ValueError: the output folder is empty; give a folder such as 'gallery'
    """
    if str(out_dir).strip() == "":
        raise ValueError("the output folder is empty; give a folder such as 'gallery'")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"the output folder {str(out)!r} is a file")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise NotADirectoryError(
            f"cannot create the output folder {str(out)!r}: a part of its path is a file"
        ) from None
    except OSError as exc:
        raise type(exc)(
            f"cannot create the output folder {str(out)!r}: {exc.strerror or exc}"
        ) from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise PermissionError(f"the output folder {str(out)!r} is not writable")
    return out


def check_sections(sections: list[str] | None) -> list[str]:
    """The known gallery sections (imports the figure modules, so needs matplotlib).

    Raises:
        ValueError: a name in ``sections`` is not a section, or ``sections`` is empty.

    Example:
        >>> check_sections(["curves"])[:2]
        ['cameras', 'curves']
        >>> check_sections(["bogus"])  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: unknown gallery section 'bogus'; the sections are cameras, curves, ...
    """
    load_figure_modules()
    known = sorted({f.section for f in registered_figures()})
    if sections is not None and len(sections) == 0:
        raise ValueError(f"no section given; the sections are {', '.join(known)}")
    unknown = [s for s in sections or [] if s not in known]
    if unknown:
        names = ", ".join(repr(s) for s in unknown)
        raise ValueError(
            f"unknown gallery section{'s' if len(unknown) > 1 else ''} {names}; "
            f"the sections are {', '.join(known)}"
        )
    return known


def _write_index(out: Path, done: list[GalleryFigure], failed: list[tuple[GalleryFigure, str]]):
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>torchgeo_cg gallery</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "figure{display:inline-block;width:520px;vertical-align:top;margin:8px}"
        "img{max-width:100%;border:1px solid #ddd}figcaption{font-size:14px}</style>",
        "</head><body><h1>torchgeo_cg gallery</h1>",
    ]
    section = None
    for fig in done:
        if fig.section != section:
            section = fig.section
            parts.append(f"<h2>{html.escape(section)}</h2>")
        parts.append(
            f"<figure><img src='{html.escape(fig.filename)}' alt='{html.escape(fig.title)}'>"
            f"<figcaption><b>{html.escape(fig.title)}.</b> {html.escape(fig.caption)}"
            "</figcaption></figure>"
        )
    if failed:
        parts.append("<h2>Figures that failed</h2><ul>")
        parts += [f"<li>{html.escape(f.filename)}: {html.escape(e)}</li>" for f, e in failed]
        parts.append("</ul>")
    parts.append("</body></html>")
    (out / "index.html").write_text("\n".join(parts), encoding="utf-8")


def build_gallery(
    out_dir: str | Path = "gallery",
    sections: list[str] | None = None,
    progress: bool = True,
) -> list[Path]:
    """Render the registered figures into ``out_dir`` and write ``index.html``.

    Args:
        out_dir: output folder, created if missing.
        sections: only these sections (``None``: all).
        progress: show a tqdm progress bar.

    Returns:
        The paths written, ``index.html`` last.

    Raises:
        ValueError: ``out_dir`` is empty, or a section is unknown.
        OSError: ``out_dir`` is a file, lies under a file or is not writable.
        RuntimeError: after writing the index, if any figure failed to render.
    """
    import matplotlib

    matplotlib.use("Agg")
    from tqdm.auto import tqdm

    out = check_output_folder(out_dir)
    check_sections(sections)
    figures = [f for f in registered_figures() if sections is None or f.section in sections]
    figures.sort(key=lambda f: f.section)
    done: list[GalleryFigure] = []
    failed: list[tuple[GalleryFigure, str]] = []
    bar = tqdm(figures, desc="gallery", unit="fig", disable=not progress)
    for fig in bar:
        bar.set_postfix_str(fig.filename)
        try:
            fig.render(out / fig.filename)
            done.append(fig)
        except Exception as exc:  # noqa: BLE001 - reported in the index and re-raised below
            failed.append((fig, f"{type(exc).__name__}: {exc}"))
        finally:
            import matplotlib.pyplot as plt

            plt.close("all")
    _write_index(out, done, failed)
    if failed:
        msg = "; ".join(f"{f.filename}: {e}" for f, e in failed)
        raise RuntimeError(f"gallery: {len(failed)} figure(s) failed: {msg}")
    return [out / f.filename for f in done] + [out / "index.html"]
