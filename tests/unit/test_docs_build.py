"""The guide builds with `mkdocs build --strict` (a broken link, a page missing from the nav
or a missing included file fails), and its hook turns links to source files into paths."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from deploy.docs_links import on_page_markdown

pytestmark = pytest.mark.timeout(120)
ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.realtime
def test_guide_builds_strict(tmp_path: Path) -> None:
    pytest.importorskip("mkdocs")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site"),
         "--config-file", str(ROOT / "mkdocs.yml")],
        capture_output=True, text=True, cwd=ROOT, timeout=100,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert (tmp_path / "site" / "simulator-ci" / "index.html").exists()
    page = (tmp_path / "site" / "simulator-ci" / "index.html").read_text()
    assert "enclose_sim" in page and "mavlink_connection" in page  # the test file, included


def hooked(markdown: str) -> str:
    page = SimpleNamespace(file=SimpleNamespace(src_path="guide/page.md"))
    return on_page_markdown(markdown, page, {"docs_dir": str(ROOT / "docs")}, None)


def test_links_to_source_files_become_their_paths() -> None:
    text = hooked("see [the reader](../../agents/loading/scenario_file.py#L1) and "
                  "![x](../../a.png)")
    assert text == "see the reader (`agents/loading/scenario_file.py`) and ![x](../../a.png)"
    assert hooked("[`pyproject.toml`](../../pyproject.toml)") == "`pyproject.toml`"


def test_links_to_missing_files_stay_for_strict_to_catch() -> None:
    for text in ("[gone](../../agents/nothing.py)", "[up](../../../../etc/passwd)"):
        assert hooked(text) == text
