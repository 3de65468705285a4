"""The documentation runs as written.

Every fenced ```python block in ``docs/*.md``, ``docs/howto/*.md`` and ``README.md`` is
executed, one file's blocks in order in one namespace, the way a reader would paste them into
one session. Each file runs in its own temporary working directory holding a copy of
``examples/`` (so the snippets use the same relative paths as a reader in the repository
checkout, and whatever they write lands in the temporary directory, never in the checkout).
```toml blocks must parse, and every fence must say what it holds: shell commands are
```bash, file trees and listings ```text.
"""

from __future__ import annotations

import re
import shutil
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC_FILES = [
    *sorted((ROOT / "docs").glob("*.md")),
    *sorted((ROOT / "docs" / "howto").glob("*.md")),  # the documentation site's how-to guides
    *sorted((ROOT / "docs" / "explain").glob("*.md")),  # the explanation pages
    ROOT / "README.md",
]

#: Fence languages a doc may use; anything else (including a bare fence) is an error, so that
#: code cannot slip past this test under an unexpected tag.
KNOWN_LANGUAGES = {"python", "toml", "bash", "text"}

_FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>.*)$")


@dataclass(frozen=True)
class Block:
    """One fenced code block of a Markdown file."""

    language: str
    source: str
    line: int  # 1-based line number of the first line of the block's content


def fenced_blocks(text: str) -> list[Block]:
    """All fenced code blocks of a Markdown text, in order (CommonMark fences, no nesting)."""
    blocks: list[Block] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        fence, indent = m["fence"], len(m["indent"])
        language = m["info"].strip().split(" ")[0].lower() if m["info"].strip() else ""
        start = i + 1
        j = start
        while j < len(lines):
            close = _FENCE.match(lines[j])
            if (
                close is not None
                and close["fence"][0] == fence[0]
                and len(close["fence"]) >= len(fence)
                and not close["info"].strip()
            ):
                break
            j += 1
        else:
            raise ValueError(f"unclosed code fence opened on line {i + 1}")
        pad = " " * indent
        body = [line[indent:] if line.startswith(pad) else line.lstrip(" ") for line in lines[start:j]]
        blocks.append(Block(language, "\n".join(body) + "\n", start + 1))
        i = j + 1
    return blocks


def run_python_blocks(blocks: list[Block], filename: str) -> dict[str, object]:
    """Execute the python blocks in order in one namespace; tracebacks name the doc's lines."""
    namespace: dict[str, object] = {"__name__": "__doc_snippet__"}
    for block in blocks:
        if block.language != "python":
            continue
        # Pad with blank lines so that line numbers in a traceback are the Markdown file's.
        code = compile("\n" * (block.line - 1) + block.source, filename, "exec")
        exec(code, namespace)
    return namespace


def _has_python(path: Path) -> bool:
    return any(b.language == "python" for b in fenced_blocks(path.read_text(encoding="utf-8")))


PY_DOCS = [p for p in DOC_FILES if _has_python(p)]


# --- the harness itself can fail -------------------------------------------------------------

_SAMPLE = """\
text
```python
x = 1
```

    indented code is not a fence
~~~toml
a = 2
~~~
```bash
echo hi
```
````text
```python
not a block of its own
```
````
"""


def test_fenced_blocks_finds_languages_lines_and_nested_fences() -> None:
    blocks = fenced_blocks(_SAMPLE)
    assert [b.language for b in blocks] == ["python", "toml", "bash", "text"]
    assert blocks[0] == Block("python", "x = 1\n", 3)
    assert blocks[1].source == "a = 2\n"
    assert blocks[3].source == "```python\nnot a block of its own\n```\n"


def test_unclosed_fence_is_an_error() -> None:
    with pytest.raises(ValueError, match="line 2"):
        fenced_blocks("a\n```python\nx = 1\n")


def test_blocks_share_a_namespace_and_failures_point_at_the_doc_line() -> None:
    text = "```python\nx = 2\n```\n\n```python\ny = x * 3\nraise RuntimeError(y)\n```\n"
    with pytest.raises(RuntimeError, match="6") as info:
        run_python_blocks(fenced_blocks(text), "doc.md")
    tb = info.traceback[-1]
    assert Path(str(tb.path)).name == "doc.md"
    assert tb.lineno + 1 == 7  # pytest's lineno is 0-based


def test_the_docs_contain_python_examples() -> None:
    assert len(PY_DOCS) >= 5, [p.name for p in PY_DOCS]


# --- the docs ---------------------------------------------------------------------------------


@pytest.fixture
def doc_workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A temporary working directory with a copy of ``examples/``; non-interactive plotting."""
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    return tmp_path


@pytest.mark.parametrize("doc", DOC_FILES, ids=[str(p.relative_to(ROOT)) for p in DOC_FILES])
def test_doc_fences_are_tagged_and_toml_parses(doc: Path) -> None:
    for block in fenced_blocks(doc.read_text(encoding="utf-8")):
        where = f"{doc.relative_to(ROOT)}:{block.line}"
        assert block.language in KNOWN_LANGUAGES, (
            f"{where}: fence language {block.language!r}; use one of {sorted(KNOWN_LANGUAGES)}"
        )
        if block.language == "toml":
            try:
                tomllib.loads(block.source)
            except tomllib.TOMLDecodeError as exc:
                pytest.fail(f"{where}: TOML block does not parse: {exc}")


@pytest.mark.parametrize("doc", PY_DOCS, ids=[str(p.relative_to(ROOT)) for p in PY_DOCS])
def test_doc_python_blocks_run(doc: Path, doc_workdir: Path) -> None:
    run_python_blocks(fenced_blocks(doc.read_text(encoding="utf-8")), str(doc))
