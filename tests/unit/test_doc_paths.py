"""Every path the documents name in backticks exists in the repository.

BENCHMARKS.md, README.md and docs/*.md name files in inline code (`agents/law/paper.py`,
`python bench/bench_core.py --repeat 2`). A token is a path when it contains '/' or ends in a
file extension; it is checked against the tree (relative to the repository's root, or to the
document's folder for a link such as `../agents/law/paper.py`). `python -m MODULE` names a
module, checked as one. What a run writes (runs/..., metrics.json), machine paths
(/tmp/..., /proc/...), placeholders (<pid>, RUN_DIR) and Zenoh key expressions are not files
of the tree, and are let through by the explicit rules below.
"""

from __future__ import annotations

import fnmatch
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(30)
ROOT = Path(__file__).resolve().parents[2]
DOCUMENTS = [ROOT / "BENCHMARKS.md", ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
EXTENSIONS = (".py", ".toml", ".md", ".sh", ".json", ".json5", ".yml", ".yaml", ".csv",
              ".png", ".txt", ".mcap", ".parquet", ".xml", ".cfg", ".ini", ".jsonl", ".zst")
# Folders not part of the tree: built, installed or written by a run.
SKIP_DIRS = {".git", ".venv", "__pycache__", "site", "runs", ".mypy_cache", ".ruff_cache",
             ".pytest_cache", ".hypothesis", "enclose.egg-info"}
# Let through (fnmatch patterns over the whole token): what a run, a sweep, a bench or
# `enclose keys` writes; files a reader names for themselves; other programs' files; Zenoh
# key expressions and Zenoh's own configuration paths, written like paths.
LET_THROUGH = [
    "runs/*", "*/runs/*", "journal/*", "logs/*", "creds/*", "credentials/*", "site/*",
    ".venv/*", "metrics.json", "launch.json", "run.json", "pids.json", "results.md",
    "results_summary.csv", "series.csv", "series.parquet", "recording.mcap", "links.csv",
    "links.png", "performance.png", "trajectory.png", "error_vs_law.png", "acl.json",
    "results.csv", "heatmap_*.png", "scenario.toml", "deployment.toml", "folder/",
    "mavproxy.py",
    "enclose/*", "transport/link/*", "transport/unicast/*",
]
SPLIT = re.compile(r"[\s\"'(),\[\]=;`]+")
INLINE = re.compile(r"(?<!`)`([^`\n]+)`(?!`)")
FENCE = re.compile(r"^\s*```")
# Fenced blocks read line by line: shell commands and the pictures (docs/architecture.md).
READ_FENCES = {"bash", "sh", "console", "shell", "text"}
PLACEHOLDER = re.compile(r"[<>*{}$|^]|\.\.\.|(^|/)[A-Z][A-Z0-9_]*(/|\.|$)")


def spans(text: str) -> Iterator[str]:
    """The inline code of a markdown text, and the lines of its shell and text blocks
    (comments left out); other fenced blocks (Python, TOML) are not read."""
    fence: str | None = None
    for line in text.splitlines():
        if FENCE.match(line):
            fence = None if fence is not None else line.strip().strip("`")
        elif fence is None:
            yield from INLINE.findall(line)
        elif fence in READ_FENCES:
            yield line.split(" #", 1)[0]


def tokens(span: str) -> Iterator[str]:
    """The path-like words of one code span (a command line gives its arguments); a module
    run with `python -m` comes as "-m MODULE"."""
    words = [w for w in SPLIT.split(span) if w]
    for k, word in enumerate(words):
        if k > 1 and words[k - 1] == "-m" and words[k - 2].endswith(("python", "python3")):
            yield "-m " + word
        elif ":" in word and "::" not in word:
            continue  # a git revision, a host, an endpoint, a module:Class: not a path
        elif word.endswith(EXTENSIONS) or "/" in word:
            yield word.split("::", 1)[0]  # a test's node id names its file


def tree() -> tuple[set[str], set[str]]:
    """Every file and folder of the repository, as root-relative posix paths."""
    files: set[str] = set()
    dirs: set[str] = set()
    for path in _walk(ROOT):
        rel = path.relative_to(ROOT).as_posix()
        (dirs if path.is_dir() else files).add(rel)
    return files, dirs


def _walk(folder: Path) -> Iterator[Path]:
    for path in folder.iterdir():
        if path.name in SKIP_DIRS:
            continue
        yield path
        if path.is_dir() and not path.is_symlink():
            yield from _walk(path)


def exists(token: str, doc: Path, files: set[str], dirs: set[str]) -> bool:
    """Whether `token` names a file or folder of the tree (or is let through)."""
    tops = {p.split("/", 1)[0] for p in files | dirs}
    if token.startswith("-m "):
        module = token[3:].replace(".", "/")
        if module.split("/", 1)[0] not in tops:
            return True  # an installed module (pytest, pstats)
        return any(m in files for m in (f"{module}.py", f"{module}/__init__.py",
                                         f"{module}/__main__.py"))
    if token.startswith(("/", "~")) or PLACEHOLDER.search(token):
        return True  # a machine path or a placeholder, not a file of the tree
    if any(fnmatch.fnmatch(token, p) for p in LET_THROUGH):
        return True
    name, first = token.rstrip("/"), token.split("/", 1)[0]
    rooted = first in tops or first in {".", ".."}
    if not (token.endswith(EXTENSIONS) or token.endswith("/") or rooted):
        return True  # a ratio or a formula (m/s, 3/7), not a path
    here = (doc.parent / name).resolve()
    if here.is_relative_to(ROOT) and here.relative_to(ROOT).as_posix() in files | dirs:
        return True
    if name in files or name in dirs or rooted:
        return name in files or name in dirs  # rooted at a top-level entry: exact
    # A partial path (`recording/intake.py`, `interface.py` in a folder's row): the end
    # of some file's path.
    return any(p.endswith("/" + name) for p in files | dirs)


def dead_paths() -> list[str]:
    files, dirs = tree()
    dead = []
    for doc in DOCUMENTS:
        for span in spans(doc.read_text()):
            for token in tokens(span):
                if not exists(token, doc, files, dirs):
                    dead.append(f"{doc.relative_to(ROOT)}: `{token}` in `{span}`")
    return dead


def test_every_backticked_path_exists() -> None:
    dead = dead_paths()
    assert not dead, "paths in the documents that do not exist:\n" + "\n".join(dead)


def test_tokens_take_the_paths_of_a_command_line() -> None:
    found = list(tokens("python bench/bench_core.py --repeat 2 --out=runs/x 'a/b.toml',"))
    assert found == ["bench/bench_core.py", "runs/x", "a/b.toml"]
    assert list(tokens("python -m agents.follower.main --help")) == ["-m agents.follower.main"]
    assert list(tokens("m/s over http://example.org git show abc:X.md")) == ["m/s"]
    assert list(tokens('load("a/b.toml")')) == ["a/b.toml"]
    assert list(tokens("pytest tests/unit/test_x.py::test_y -m serial")) == [
        "tests/unit/test_x.py"]


def test_a_dead_path_is_found_and_placeholders_pass() -> None:
    files, dirs = tree()
    doc = ROOT / "BENCHMARKS.md"
    assert not exists("agents/follower_logic.py", doc, files, dirs)
    assert not exists("-m agents.follower_node", doc, files, dirs)
    assert not exists("nowhere/at_all.py", doc, files, dirs)
    assert not exists("tests/swarm_harness", doc, files, dirs)
    for ok in ("agents/law/paper.py", "deploy/", "paper.py", "recording/intake.py",
               "-m agents.follower.main", "runs/run-paper-<time>/", "/proc/<pid>/smaps",
               "OUT_DIR/operator/", "metrics.json", "enclose/<swarm>/control",
               "../agents/law/interface.py", "m/s", "3/7", "-m pytest", "DEPLOYMENT.toml"):
        assert exists(ok, ROOT / "docs" / "x.md", files, dirs), ok


def test_shell_blocks_are_read_and_other_blocks_left_out() -> None:
    text = ("a `x/y.py` b\n```bash\nrun s/t.sh  # see `c/d.py`\n```\n"
            "```python\nload('p/q.toml')\n```\nc `w.md`")
    assert list(spans(text)) == ["x/y.py", "run s/t.sh ", "w.md"]
