"""Build the gallery: render every registered figure and write ``index.html``."""

from __future__ import annotations

import html
import importlib
import pkgutil
from pathlib import Path

from torchgeo_cg.viz.registry import GalleryFigure, registered_figures

__all__ = ["build_gallery", "load_figure_modules"]

_SKIP = {"registry", "gallery", "style"}  # helpers, not figure modules


def load_figure_modules() -> list[str]:
    """Import every figure module of :mod:`torchgeo_cg.viz` (needs matplotlib)."""
    import torchgeo_cg.viz as viz

    names = []
    for info in pkgutil.iter_modules(viz.__path__):
        if info.name in _SKIP or info.name.startswith("_"):
            continue
        importlib.import_module(f"torchgeo_cg.viz.{info.name}")
        names.append(info.name)
    return names


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
        RuntimeError: after writing the index, if any figure failed to render.
    """
    import matplotlib

    matplotlib.use("Agg")
    from tqdm.auto import tqdm

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    load_figure_modules()
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
