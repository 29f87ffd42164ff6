"""The user's docs hold together: every relative link and image in README.md, docs/*.md and the
model cards points to a file that exists (and an in-page anchor to a heading of that page), the
repository cites its own pages, not a design note kept outside it, and the pages speak of the
project, not of who worked on it when."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
DOCS = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md"), *(ROOT / "models").glob("*/MODEL_CARD.md")])
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
EXTERNAL = ("http://", "https://", "mailto:")


def links(text: str) -> list[str]:
    """Targets of the markdown links and images in `text`, code spans and fenced blocks left out."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    text = re.sub(r"`[^`\n]*`", "", text)
    return LINK.findall(text)


def anchor(heading: str) -> str:
    """GitHub's anchor of a markdown heading's text."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    return {anchor(m) for m in re.findall(r"^#+ (.+)$", path.read_text(), flags=re.M)}


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(doc):
    broken = []
    for target in links(doc.read_text()):
        if target.startswith(EXTERNAL):
            continue
        path, _, fragment = target.partition("#")
        file = (doc.parent / path).resolve() if path else doc
        if not file.exists():
            broken.append(target)
        elif fragment and file.suffix == ".md" and fragment not in anchors(file):
            broken.append(target)
    assert not broken, f"{doc.relative_to(ROOT)}: links to nothing: {broken}"


def test_no_page_or_source_cites_design_md():
    sources = [*DOCS, *(ROOT / "nfr_drake").rglob("*.py"), *(ROOT / "tutorials").glob("*.py"),
               *(ROOT / "benchmarks").glob("*.py"), *(ROOT / "systems").glob("*.py")]
    citing = [str(p.relative_to(ROOT)) for p in sources if "DESIGN.md" in p.read_text()]
    assert not citing, f"cite docs/CONVENTIONS.md instead of DESIGN.md: {citing}"


def test_the_docs_speak_of_the_project_only():
    """Results and history belong to the project; who worked when is for commit messages."""
    naming = [f"{p.relative_to(ROOT)}:{i}" for p in DOCS
              for i, line in enumerate(p.read_text().splitlines(), 1)
              if re.search(r"\bsessions?\b|\bhelper-\d+\b", line, flags=re.I)]
    assert not naming, f"pages that speak of sessions or helpers: {naming}"


def test_the_checker_finds_links_and_anchors():
    text = "See [a](docs/A.md#b-c), ![img](images/x.png), `[not](code.md)` and [web](https://x.org).\n"
    assert links(text) == ["docs/A.md#b-c", "images/x.png", "https://x.org"]
    assert anchor("The handle detector's triangulated handle") == "the-handle-detectors-triangulated-handle"
    assert anchor("Fitting unseen objects: the neural field") == "fitting-unseen-objects-the-neural-field"
