"""Writing a figure as the project writes them all: the file asked for and a PDF beside it."""

from pathlib import Path


def save_with_pdf(fig, path, dpi: int = 110) -> None:
    """Save `fig` to `path` (PNG, or the format its suffix names) at `dpi`, and as a PDF beside
    it (same name, .pdf) unless `path` is the PDF."""
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    if path.suffix.lower() != ".pdf":
        fig.savefig(path.with_suffix(".pdf"))
