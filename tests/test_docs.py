"""Every Python block of the guides in docs/ runs as written (public API only), like the README's."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
GUIDES = ("ik.md", "timing.md", "streaming.md", "reference.md", "cli.md", "ros.md", "planning.md", "perception.md")
_BLOCK = re.compile(r"^```python\n(.*?)^```", flags=re.S | re.M)


def _blocks() -> list[tuple[str, int, str]]:
    out = []
    for path in sorted(DOCS.glob("*.md")):
        text = path.read_text()
        for match in _BLOCK.finditer(text):
            line = text.count("\n", 0, match.start()) + 2  # first line of the code
            out.append((path.name, line, match.group(1)))
    return out


BLOCKS = _blocks()


@pytest.mark.parametrize(("name", "line", "code"), BLOCKS, ids=[f"{n}:{line}" for n, line, _ in BLOCKS])
def test_docs_block_runs(name, line, code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # examples may write files
    monkeypatch.setenv("MPLBACKEND", "Agg")
    source = "\n" * (line - 1) + code  # tracebacks point at the line in the guide
    exec(compile(source, str(DOCS / name), "exec"), {"__name__": "__docs__"})


@pytest.mark.parametrize("guide", GUIDES)
def test_each_capability_has_a_guide_with_examples(guide):
    path = DOCS / guide
    assert path.is_file(), f"docs/{guide} is missing"
    text = path.read_text()
    assert "## Limitations" in text
    if guide != "cli.md":
        assert _BLOCK.search(text), f"docs/{guide} has no ```python example"


def test_guides_link_only_to_existing_files():
    for path in DOCS.glob("*.md"):
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", path.read_text()):
            if "://" in target:
                continue
            assert (path.parent / target).exists(), f"{path.name} links to missing {target}"
