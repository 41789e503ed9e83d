"""A hook of the guide's build (mkdocs.yml `hooks`): links from a page to the project's own
files outside docs/ (`[the interface](../agents/law/interface.py)`) become the file's path
in code, as the site has no copy of them to link to. A link to a file that does not exist
is left as it is, so that `mkdocs build --strict` still fails on it."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

LINK = re.compile(r"(?<!!)\[([^\]]+)\]\((\.\./[^)#\s]+)(#[^)\s]*)?\)")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    docs = Path(config["docs_dir"]).resolve()
    here = (docs / page.file.src_path).parent
    return LINK.sub(lambda m: source_text(m, here, docs.parent), markdown)


def source_text(match: re.Match[str], here: Path, root: Path) -> str:
    text, target = match.group(1), match.group(2)
    path = (here / target).resolve()
    if not path.exists() or not path.is_relative_to(root):
        return match.group(0)
    shown = path.relative_to(root).as_posix()
    return text if text.strip("`") == shown else f"{text} (`{shown}`)"
