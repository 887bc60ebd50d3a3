"""MkDocs build hook: keeps the API reference in step with the packages' modules.

The pages under ``api/`` list modules with mkdocstrings directives (``::: mpg_envs.tasks.env``),
grouped by topic. At build time this hook drops a directive whose module no longer exists
(the module was renamed or moved) and puts every public module that no page lists on
``api/other.md``, so a module is never left out of the reference and a move never breaks
the build. Moving a module to the page of its topic is then an edit of that page.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("mpg_envs", "mpg_agents")
OTHER_PAGE = "api/other.md"
DIRECTIVE = re.compile(r"^::: ([\w.]+)[ \t]*$", re.MULTILINE)

log = logging.getLogger("mkdocs.hooks.api_reference")


def public_modules() -> list[str]:
    """Every importable module of the packages whose dotted name has no ``_``-prefixed part."""
    modules = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if not (path.parent / "__init__.py").is_file():
                continue
            parts = path.relative_to(ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if any(part.startswith("_") for part in parts):
                continue
            modules.append(".".join(parts))
    return modules


def listed_modules(docs_dir: Path) -> set[str]:
    """The modules the topic pages of ``api/`` name in their directives."""
    names: set[str] = set()
    for page in sorted((docs_dir / "api").glob("*.md")):
        if page.relative_to(docs_dir).as_posix() != OTHER_PAGE:
            names.update(DIRECTIVE.findall(page.read_text()))
    return names


def on_page_markdown(markdown: str, page, config, files) -> str:
    src = page.file.src_uri
    if not src.startswith("api/"):
        return markdown
    modules = public_modules()
    present = set(modules)

    def keep(match: re.Match) -> str:
        if match.group(1) in present:
            return match.group(0)
        log.info("API reference: %s names %s, which no longer exists; left out", src, match.group(1))
        return ""

    markdown = DIRECTIVE.sub(keep, markdown)
    if src == OTHER_PAGE:
        listed = listed_modules(Path(config["docs_dir"]))
        rest = [m for m in modules if m not in listed]
        markdown += "\n" + ("\n".join(f"::: {m}\n" for m in rest) if rest else "Every module is on one of the pages above.\n")
    return markdown
