"""The docs' navigation stays true to the docs: RESULTS.md's contents list every section."""

import re
from pathlib import Path

RESULTS = Path(__file__).parents[1] / "docs" / "RESULTS.md"


def _slug(title: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to dashes."""
    return re.sub(r"[^\w\- ]", "", title.lower().replace("`", "")).replace(" ", "-")


def test_results_contents_link_every_section():
    text = RESULTS.read_text()
    contents, body = text.split("## Contents", 1)[1].split("\n## ", 1)
    headings = re.findall(r"^#{2,3} (.+)$", "## " + body, flags=re.M)
    links = re.findall(r"\]\(#([^)]+)\)", contents)
    assert links == [_slug(h) for h in headings], (
        "docs/RESULTS.md's Contents do not match its sections: add the new section's line")
