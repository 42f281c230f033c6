"""The Python examples of the README and of docs/ run as written, and the README's links
lead somewhere."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCKS = [
    (page, block)
    for page in PAGES
    for block in re.findall(
        r"^```python\n(.*?)^```$", page.read_text(encoding="utf-8"), re.M | re.S
    )
]


def test_the_readme_and_the_docs_have_python_examples() -> None:
    readme = [b for page, b in BLOCKS if page.name == "README.md"]
    assert len(readme) >= 1 and len(BLOCKS) >= 3


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_python_block_runs(index: int, capsys: pytest.CaptureFixture[str]) -> None:
    page, block = BLOCKS[index]
    exec(compile(block, f"{page.name} python block {index}", "exec"), {})
    assert capsys.readouterr().out.strip(), "each example prints what it shows"


def test_the_readme_starts_a_newcomer_in_one_screen() -> None:
    """Issue 22: what the tool does, the two commands, where the result is and what its
    numbers mean come first; the node next; details in docs/."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    order = [
        "## Two commands",
        "replay_output/report/index.html",
        "**play**",
        "## The ROS 2 node",
        "## More",
    ]
    places = [text.index(marker) for marker in order]
    assert places == sorted(places)
    assert len(text.splitlines()) < 150
    for link in re.findall(r"\]\(([^)#]+)\)", text):
        assert (ROOT / link).exists(), link
