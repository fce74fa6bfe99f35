from pathlib import Path

from fiberpipe.config import reference_markdown

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_config_reference_is_current():
    """docs/config.md must list every key the validator knows (regenerate: see its header)."""
    text = (DOCS / "config.md").read_text()
    assert reference_markdown() in text, (
        "docs/config.md is stale: run  ( cat docs/config.head.md; python -c 'from fiberpipe.config import "
        "reference_markdown; print(reference_markdown())' ) > docs/config.md"
    )
