"""Every code snippet of README.md and of the guide (docs/**/*.md) runs, and the
documented version is the built one.

The blocks of a page run in page order, in one temporary directory holding a copy of
the repository's experiments/ and examples/, so that a later block reads what an
earlier one wrote (as a reader following the page would):

- ```python blocks run in one namespace per page;
- ```sh / ```bash / ```console blocks whose first command starts with `smspace` run
  in bash, with the command-line tool (``$SMSPACE_CLI``, as the other tests) as
  `smspace` and this interpreter as `python3`; other shell blocks are installation
  and build commands, which CI runs itself;
- a block after ``<!-- snippet: requires MODULE -->`` is self-contained and runs as a
  test of its own where MODULE imports (skipped with the reason elsewhere); one after
  ``<!-- snippet: skip REASON -->`` never runs (a skipped test saying why).

```rust blocks are doc tests of the Rust library (`cargo test --doc`); ```toml and
```text blocks are not code to run.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional

import pytest

ROOT = Path(__file__).resolve().parents[3]
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
SHELLS = ("sh", "bash", "console", "shell")
MARKER = re.compile(r"<!--\s*snippet:\s*(skip|requires)\s+(.*?)\s*-->")
FENCE = re.compile(r"^(`{3,})\s*([\w+-]*)")


@dataclass
class Block:
    """A fenced code block: its language, code, the line of its opening fence (1-based)
    and its marker (``("skip", reason)``, ``("requires", module)``) if any."""

    page: Path
    lang: str
    code: str
    line: int
    marker: Optional[tuple] = None

    @property
    def name(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"

    def runs(self) -> bool:
        """Whether this block is code the test runs (see the module's docs)."""
        if self.lang == "python":
            return True
        if self.lang in SHELLS:
            commands = [
                line.strip().lstrip("$ ").strip()
                for line in self.code.splitlines()
                if line.strip() and not line.strip().startswith("#")
            ]
            return bool(commands) and commands[0].startswith("smspace ")
        return False


def blocks(page: Path) -> List[Block]:
    """The fenced code blocks of a Markdown page, with the marker on the last
    non-blank line before each."""
    found: List[Block] = []
    lines = page.read_text(encoding="utf-8").splitlines()
    previous = ""
    i = 0
    while i < len(lines):
        opening = FENCE.match(lines[i].strip())
        if not opening:
            if lines[i].strip():
                previous = lines[i].strip()
            i += 1
            continue
        fence, lang = opening.group(1), opening.group(2).lower()
        start = i + 1
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence):
            i += 1
        marker = MARKER.fullmatch(previous)
        found.append(
            Block(
                page=page,
                lang=lang,
                code="\n".join(lines[start:i]) + "\n",
                line=start,
                marker=(marker.group(1), marker.group(2)) if marker else None,
            )
        )
        previous = ""
        i += 1
    return found


def _cli() -> str:
    found = os.environ.get("SMSPACE_CLI") or shutil.which("smspace")
    if not found or not Path(found).exists():
        if os.environ.get("SMSPACE_REQUIRE_CLI"):
            raise RuntimeError("SMSPACE_CLI does not name the smspace binary")
        pytest.skip("the smspace command-line tool is not built (set SMSPACE_CLI)")
    return str(Path(found).resolve())


def _workdir(tmp: Path) -> dict:
    """A reader's working directory (copies of experiments/ and examples/) and the
    environment of its shell: `smspace` and `python3` first on the PATH."""
    for folder in ("experiments", "examples"):
        shutil.copytree(ROOT / folder, tmp / folder)
    bin_dir = tmp / ".bin"
    bin_dir.mkdir()
    (bin_dir / "smspace").symlink_to(_cli())
    for name in ("python3", "python"):
        # A wrapper, not a link: a virtual environment's interpreter finds its
        # packages from the path it is started by.
        wrapper = bin_dir / name
        wrapper.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
        wrapper.chmod(0o755)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    return env


def _run(block: Block, cwd: Path, env: dict, namespace: dict) -> None:
    if block.lang == "python":
        code = compile(block.code, block.name, "exec")
        previous = os.getcwd()
        os.chdir(cwd)
        try:
            exec(code, namespace)  # noqa: S102 - the documented snippet itself
        finally:
            os.chdir(previous)
        return
    done = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", block.code],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert done.returncode == 0, (
        f"{block.name}: the shell snippet failed ({done.returncode}):\n{block.code}\n"
        f"stdout:\n{done.stdout[-4000:]}\nstderr:\n{done.stderr[-4000:]}"
    )


def _page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


def _all_blocks() -> List[Block]:
    return [block for page in PAGES for block in blocks(page) if block.runs()]


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_the_snippets_of_a_page_run_in_order(page, tmp_path):
    runnable = [b for b in blocks(page) if b.runs() and b.marker is None]
    if not runnable:
        pytest.skip(f"{_page_id(page)} has no snippet to run")
    env = _workdir(tmp_path)
    namespace: dict = {"__name__": "__snippet__"}
    for block in runnable:
        _run(block, tmp_path, env, namespace)


MARKED = [b for b in _all_blocks() if b.marker is not None]


@pytest.mark.parametrize("block", MARKED, ids=[b.name for b in MARKED])
def test_a_snippet_that_needs_something_optional_runs_where_it_is_there(block, tmp_path):
    kind, what = block.marker
    if kind == "skip":
        pytest.skip(f"{block.name}: {what}")
    missing = [m for m in what.replace(",", " ").split() if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"{block.name} needs {', '.join(missing)} (not installed)")
    env = _workdir(tmp_path)
    _run(block, tmp_path, env, {"__name__": "__snippet__"})


# --- the extractor and the pages' shape -----------------------------------------------


def test_the_extractor_finds_blocks_markers_and_what_runs(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "Text\n\n```python\nx = 1\n```\n\n<!-- snippet: requires mujoco -->\n"
        "```python\nimport mujoco\n```\n\n```sh\n# a comment\nsmspace run a.toml\n```\n\n"
        "```sh\ncargo build\nsmspace run a.toml\n```\n\n<!-- snippet: skip needs a cluster -->\n"
        "```bash\nsmspace x\n```\n\n```toml\n[agent]\n```\n",
        encoding="utf-8",
    )
    found = blocks(page)
    assert [b.lang for b in found] == ["python", "python", "sh", "sh", "bash", "toml"]
    assert [b.runs() for b in found] == [True, True, True, False, True, False]
    assert found[0].marker is None and found[0].line == 3 and found[0].code == "x = 1\n"
    assert found[1].marker == ("requires", "mujoco")
    assert found[4].marker == ("skip", "needs a cluster")


def test_the_readme_is_short_and_names_the_test_command_ci_runs():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    # .ci/run greps the first line starting with `scripts/test` or `cargo test`.
    first = next(
        line for line in text.splitlines() if re.match(r"^(scripts/test|cargo test)", line)
    )
    assert first == "scripts/test"


def test_the_readme_lists_every_shipped_experiment():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\| `([\w-]+\.toml)` \|", text, flags=re.M))
    shipped = {p.name for p in (ROOT / "experiments").glob("*.toml")}
    assert listed == shipped


def test_the_docs_speak_of_the_software_not_of_its_history():
    """README and every guide page."""
    pattern = re.compile(r"\b(issue \d+|issues? #?\d+|(\w+th|first|second|third) session)\b", re.I)
    for page in PAGES:
        hits = pattern.findall(page.read_text(encoding="utf-8"))
        assert not hits, f"{_page_id(page)} names development history: {hits}"


# --- the version ------------------------------------------------------------------------


def _workspace_version() -> str:
    text = (ROOT / "Cargo.toml").read_text(encoding="utf-8")
    section = text.split("[workspace.package]", 1)[1]
    return re.search(r'^version = "([^"]+)"', section, flags=re.M).group(1)


def test_the_version_is_the_workspace_s_and_the_changelog_s():
    import smspace

    version = _workspace_version()
    assert smspace.__version__ == version
    assert importlib.metadata.version("smspace") == version
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert re.search(r"^## (\S+)", changelog, flags=re.M).group(1) == version


def test_the_command_line_tool_reports_the_same_version(cli):
    assert cli("--version").stdout.strip() == f"smspace {_workspace_version()}"
