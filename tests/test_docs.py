"""The documents a lab measuring its own recording follows (issue 20: the README and
config/README.md pointed to docs that were not in the repository): every relative link in them
resolves, to a heading where it names one, and the complete example test.yaml of
docs/test-folder.md is valid as written."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from triaxtrack.errors import schema_problems, unknown_top_level_keys

REPO = Path(__file__).resolve().parents[1]
DOCUMENTS = [REPO / "README.md", REPO / "config" / "README.md", *sorted((REPO / "docs").glob("*.md")),
             REPO / "src" / "triaxtrack" / "KIT_README.md"]  # fmt: skip
GUIDES = ("measure-your-own-test.md", "test-folder.md", "target-kit.md")


def heading_anchors(markdown: str) -> set[str]:
    """GitHub's anchors of the headings (not the comments of code blocks): lower case,
    punctuation dropped, spaces to hyphens."""
    prose = re.sub(r"^```.*?^```", "", markdown, flags=re.MULTILINE | re.DOTALL)
    headings = re.findall(r"^#+\s+(.*?)\s*$", prose, flags=re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-") for h in headings}


def relative_links(path: Path) -> list[str]:
    links = re.findall(r"\]\(([^)\s]+)\)", path.read_text())
    return [link for link in links if not re.match(r"[a-z][a-z0-9+.-]*:", link)]


def test_the_guides_are_in_the_repository_and_linked_from_the_readme():
    readme = (REPO / "README.md").read_text()
    for name in GUIDES:
        assert (REPO / "docs" / name).stat().st_size > 1000, name
        assert f"docs/{name}" in readme, name


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(document):
    broken = []
    for link in relative_links(document):
        path, _, anchor = link.partition("#")
        target = (document.parent / path) if path else document
        if not target.exists():
            broken.append(f"{link}: no such file")
        elif anchor and target.suffix == ".md" and anchor not in heading_anchors(target.read_text()):
            broken.append(f"{link}: no such heading")
    assert not broken, broken


def test_the_example_test_yaml_is_valid():
    """The complete example of docs/test-folder.md (the first YAML block holding `cameras`): no
    schema problem, and only the key it says is not read draws a warning."""
    blocks = re.findall(r"```yaml\n(.*?)```", (REPO / "docs" / "test-folder.md").read_text(), flags=re.DOTALL)
    example = next(doc for doc in map(yaml.safe_load, blocks) if isinstance(doc, dict) and "cameras" in doc)
    schema = yaml.safe_load((REPO / "workflow" / "schemas" / "test.schema.yaml").read_text())
    assert schema_problems(example, schema, [("test.yaml", example)]) == []
    assert unknown_top_level_keys(example, schema) == ["'operator'"]
    assert len(example["cameras"]) == 13
