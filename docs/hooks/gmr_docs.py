"""mkdocs hook: build results/ and notebooks/ into the site from where they live.

mkdocs reads pages from `docs_dir` only, and both folders sit at the repository root (results/ is
written by studies/ and benchmarks/, notebooks/ is executed by the tests). Rather than copy
them, this hook adds their files to the build with the repository root as their source folder,
so `results/README.md`, its tables and `results/figures/*.png` keep their relative links, and
mkdocs-jupyter renders every `notebooks/*.ipynb` (the "Notebooks" nav section is filled from
the folder, so a new notebook appears without editing mkdocs.yml).
"""

import json
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

# folder -> file suffixes taken from it (results/data/ holds large generated outputs: not built)
_TREES = {"results": (".md", ".png", ".svg", ".jpg"), "notebooks": (".ipynb",)}
_SKIP = {"data", ".ipynb_checkpoints"}


def _root(config) -> Path:
    return Path(config.config_file_path).resolve().parent


def _sources(root: Path, folder: str):
    suffixes = _TREES[folder]
    for path in sorted((root / folder).rglob("*")):
        rel = path.relative_to(root)
        if path.is_file() and path.suffix in suffixes and not _SKIP.intersection(rel.parts[1:-1]):
            yield rel.as_posix()


def on_config(config):
    """Fill the "Notebooks" and "Results" nav sections from the folders."""
    root = _root(config)
    sections = {
        "Notebooks": [{_title(root / p): p} for p in _sources(root, "notebooks")],
        "Results": ["results/README.md", {"Figures": _GALLERY}] + [
            {p.split("/")[-1]: p} for p in _sources(root, "results")
            if p.endswith(".md") and p != "results/README.md"
        ],
    }
    for i, entry in enumerate(config.nav or []):
        if isinstance(entry, dict) and len(entry) == 1:
            (name,) = entry
            if name in sections:
                config.nav[i] = {name: sections[name]}
    return config


def _title(path: Path) -> str:
    """The first level-1 Markdown heading (of a page, or of a notebook's cells), else the file name."""
    try:
        text = path.read_text(encoding="utf-8")
        if path.suffix == ".ipynb":
            cells = json.loads(text)["cells"]
            text = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
        for line in text.splitlines():
            if line.startswith("# "):
                return line[2:].strip()
    except (ValueError, KeyError, OSError):
        pass
    return path.stem


@event_priority(100)  # before mkdocs-jupyter's on_files, which wraps the .ipynb files it sees
def on_files(files, config):
    root = _root(config)
    for folder in _TREES:
        for rel in _sources(root, folder):
            if files.get_file_from_path(rel) is None:
                files.append(File(rel, src_dir=str(root), dest_dir=config.site_dir,
                                  use_directory_urls=config.use_directory_urls))
    files.append(File.generated(config, _GALLERY, content=_gallery(root)))
    return files


_GALLERY = "results/figures.md"


def _gallery(root: Path) -> str:
    """A page showing every figure in results/figures/, each under its file name, with the result
    tables that refer to it."""
    tables = {p: (root / p).read_text(encoding="utf-8") for p in _sources(root, "results") if p.endswith(".md")}
    lines = ["# Figures", "", "Every figure in `results/figures/`, as the studies wrote it; the tables that",
             "show it are linked under each one.", ""]
    for rel in _sources(root, "results"):
        if not rel.startswith("results/figures/") or rel.endswith(".md"):
            continue
        name = rel.split("/")[-1]
        used = [p.split("/")[-1] for p, text in tables.items() if f"figures/{name}" in text]
        lines += [f"## {name}", "", f"![{name}](figures/{name})", ""]
        if used:
            lines += ["In: " + ", ".join(f"[{u}]({u})" for u in used), ""]
    return "\n".join(lines)


_CLI_MARKER = "<!-- gmr-cli-help -->"


def on_page_markdown(markdown, page, config, files):
    """Replace the CLI marker with every subcommand's `--help` text, from the parser itself."""
    if _CLI_MARKER not in markdown:
        return markdown
    import os

    from gmr_jax._cli._main import build_parser

    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal width: make it fixed
    try:
        parser = build_parser()
        (sub,) = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
        parts = [f"### gmr\n\n```text\n{parser.format_help()}```\n"]
        for name, cmd in sub.choices.items():
            parts.append(f"### gmr {name}\n\n```text\n{cmd.format_help()}```\n")
    finally:
        if columns is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = columns
    return markdown.replace(_CLI_MARKER, "\n".join(parts))
