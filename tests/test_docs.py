"""The documentation: the config reference is current, every internal link and anchor of README.md,
CHANGELOG.md and docs/ resolves (on GitHub and in the mkdocs site), every page is in the site's
navigation, and the reference text speaks about the software, not about how it was written.

The markdown is parsed here (no mkdocs needed, no network): links and images outside code, heading
anchors as python-markdown's ``toc`` extension and GitHub make them, and explicit ``<a id>`` /
``{#id}`` anchors.
"""

import re
import unicodedata
from pathlib import Path

import pytest
import yaml

from fiberpipe.config import reference_markdown

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", *DOCS.rglob("*.md")])
NOT_IN_NAV = {"config.head.md"}  # the hand-written head of config.md, not a page of its own


def test_config_reference_is_current():
    """docs/config.md must list every key the validator knows (regenerate: make config-reference)."""
    text = (DOCS / "config.md").read_text()
    head = (DOCS / "config.head.md").read_text()
    assert text.startswith(head), "docs/config.md does not start with docs/config.head.md: run make config-reference"
    assert reference_markdown() in text, "docs/config.md is stale: run make config-reference"


# -- markdown parsing ------------------------------------------------------------------------------

FENCE = re.compile(r"^(```|~~~)")
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HTML_LINK = re.compile(r"""<(?:a|img)\b[^>]*\b(?:href|src)=["']([^"']+)["']""")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
EXPLICIT_ID = re.compile(r"""<a\s+(?:id|name)=["']([^"']+)["']|\{\s*#([\w-]+)[^}]*\}""")


def prose_lines(text: str):
    """(line number, line) outside fenced code blocks, with inline code spans blanked."""
    fenced = False
    for n, line in enumerate(text.splitlines(), 1):
        if FENCE.match(line.lstrip()):
            fenced = not fenced
            continue
        if not fenced:
            yield n, INLINE_CODE.sub(lambda m: " " * len(m.group(0)), line)


def _heading_text(raw: str) -> str:
    text = re.sub(r"\{\s*#[\w-]+[^}]*\}\s*$", "", raw)  # attr_list id, not part of the text
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", text)  # links keep their text
    text = re.sub(r"<[^>]+>", "", text)
    return text.replace("`", "").replace("**", "").replace("__", "")


def slug_mkdocs(text: str) -> str:
    """python-markdown toc's default slugify (what the mkdocs site uses)."""
    value = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    value = re.sub(r"[^\w\s-]", "", value).strip().lower()
    return re.sub(r"[-\s]+", "-", value)


def slug_github(text: str) -> str:
    """GitHub's heading anchors: lower case, punctuation dropped, each space a hyphen."""
    value = re.sub(r"[^\w\- ]", "", text.strip().lower())
    return value.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The anchors valid both on GitHub and in the site, plus the explicit ones."""
    seen_m: dict[str, int] = {}
    seen_g: dict[str, int] = {}
    found_m, found_g, explicit = set(), set(), set()
    fenced = False
    for line in path.read_text().splitlines():
        if FENCE.match(line.lstrip()):
            fenced = not fenced
            continue
        if fenced:
            continue
        for m in EXPLICIT_ID.finditer(line):
            explicit.add(m.group(1) or m.group(2))
        h = HEADING.match(line)
        if not h:
            continue
        text = _heading_text(h.group(2))
        for slug, seen, found, sep in ((slug_mkdocs(text), seen_m, found_m, "_"),
                                       (slug_github(text), seen_g, found_g, "-")):
            k = seen.get(slug, 0)
            found.add(slug if k == 0 else f"{slug}{sep}{k}")
            seen[slug] = k + 1
    return (found_m & found_g) | explicit


def links(path: Path):
    """(line number, target) of every link and image in prose."""
    for n, line in prose_lines(path.read_text()):
        for m in LINK.finditer(line):
            yield n, m.group(1)
        for m in HTML_LINK.finditer(line):
            yield n, m.group(1)


def _is_external(target: str) -> bool:
    return bool(re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I))


def broken_links(path: Path) -> list[str]:
    problems = []
    for n, target in links(path):
        if _is_external(target):
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        where = f"{path.relative_to(ROOT)}:{n}: {target}"
        if not dest.exists():
            problems.append(f"{where}: no such file")
            continue
        if path.is_relative_to(DOCS) and not dest.is_relative_to(DOCS):
            problems.append(f"{where}: leaves docs/ (the site holds only docs/; name the file as code instead)")
            continue
        if anchor:
            if dest.suffix != ".md":
                problems.append(f"{where}: anchor into a non-markdown file")
            elif anchor not in anchors(dest):
                problems.append(f"{where}: no anchor '{anchor}' in {dest.relative_to(ROOT)}")
    return problems


# -- the parser itself, on known pages ---------------------------------------------------------------

def test_the_parser_finds_links_and_anchors(tmp_path):
    page = tmp_path / "a.md"
    (tmp_path / "b.md").write_text("# Fast settings (one core)\n\n## Fast settings (one core)\n<a id=\"x-y\"></a>\n")
    page.write_text("see [b](b.md#fast-settings-one-core), ![i](img.png) `[not](c.md)`\n"
                    "```\n[fenced](d.md)\n```\n[dup](b.md#fast-settings-one-core_1) [x](b.md#x-y) [web](https://e.org)\n")
    found = [t for _, t in links(page)]
    assert found == ["b.md#fast-settings-one-core", "img.png", "b.md#fast-settings-one-core_1", "b.md#x-y", "https://e.org"]
    assert "fast-settings-one-core" in anchors(tmp_path / "b.md")
    assert "x-y" in anchors(tmp_path / "b.md")
    # the second heading is _1 in the site but -1 on GitHub: valid in only one of them
    assert "fast-settings-one-core_1" not in anchors(tmp_path / "b.md")


def test_slugs_follow_mkdocs_and_github():
    assert slug_mkdocs("Latest fiberpipe bench run") == slug_github("Latest fiberpipe bench run") == "latest-fiberpipe-bench-run"
    assert slug_mkdocs("Fiber–fiber contact") == "fiberfiber-contact"
    assert slug_github("Fiber–fiber contact") == "fiberfiber-contact"
    assert slug_mkdocs("Φ and δ") == "and"  # non-ASCII letters vanish in the site's anchors
    assert slug_github("Φ and δ") == "φ-and-δ"


# -- the repository's pages ------------------------------------------------------------------------

@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_internal_links_and_anchors_resolve(page):
    problems = broken_links(page)
    assert not problems, "\n".join(problems)


def test_every_page_is_in_the_site_navigation():
    cfg = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    listed: set[str] = set()

    def walk(node):
        if isinstance(node, str):
            listed.add(node)
        elif isinstance(node, dict):
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(cfg["nav"])
    pages = {str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")}
    assert pages - NOT_IN_NAV == listed, (f"not in mkdocs.yml nav: {sorted(pages - NOT_IN_NAV - listed)}; "
                                          f"in nav but missing: {sorted(listed - pages)}")


# -- reference text, not a lab notebook ------------------------------------------------------------

NARRATION = [
    (re.compile(r"\bSPEC\b"), "cites an outside document (link a page of docs/ instead)"),
    (re.compile(r"\.md`?\)?,? *§"), "cites a page by section number (link its heading's anchor instead)"),
    (re.compile(r"\.\./shared|runs/energy|\bnotes/"), "cites a file that is not in the repository"),
    (re.compile(r"\bissues? ?#?\d+", re.I), "cites an issue number"),
    (re.compile(r"\b(sessions?|engineers?|reviewers?|helpers?)\b", re.I), "narrates who did the work"),
    (re.compile(r"\b[Rr]ound \d\b"), "narrates rounds of work"),
    (re.compile(r"\b20\d\d-\d\d-\d\d\b"), "dated prose (history goes to CHANGELOG.md)"),
]
REFERENCE_TEXT = sorted(
    [ROOT / "README.md", *DOCS.rglob("*.md"), *(ROOT / "configs").rglob("*.yaml"),
     *(ROOT / "data-samples").glob("*/README.md"), *(ROOT / "fiberpipe" / "benchmarks").glob("*.py"),
     *(ROOT / "benchmarks").glob("*.py"),
     *(ROOT / "fiberpipe" / "io").glob("*.py"), ROOT / "fiberpipe" / "bench.py", *(ROOT / "tools").glob("*.py"),
     ROOT / "fiberpipe" / "cli.py", ROOT / "fiberpipe" / "config.py", ROOT / "fiberpipe" / "pipeline.py",
     ROOT / "Makefile"])
# pages whose narration is a known defect, each to be rewritten as reference text
NARRATING: set = set()
# a generated page's measurement stamp is data, not prose
STAMP = re.compile(r"^\s*(- date:|_Last generated)")


def narration(path: Path) -> list[str]:
    found = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if STAMP.match(line):
            continue
        for pattern, why in NARRATION:
            if pattern.search(line):
                found.append(f"{path.relative_to(ROOT)}:{n}: {why}: {line.strip()[:100]}")
    return found


@pytest.mark.parametrize("path", [
    pytest.param(p, marks=pytest.mark.xfail(strict=True, reason="known defect: the page narrates its history"))
    if str(p.relative_to(ROOT)) in NARRATING else p
    for p in REFERENCE_TEXT], ids=lambda p: str(p.relative_to(ROOT)))
def test_reference_text_does_not_narrate(path):
    found = narration(path)
    assert not found, "\n".join(found)


# the code, its comments and the tests: the same rules but "helpers" (a helper function is code) and
# pytest's fixture scope "session"
CODE_NARRATION = [(p, why) for p, why in NARRATION if "who did the work" not in why] + [
    (re.compile(r"\b(sessions?|engineers?|reviewers?)\b(?<!scope=\"session)", re.I), "narrates who did the work"),
    (re.compile(r"\b(first|second|third|last) round of work|\b(first|second|third)( and \w+)? round\b", re.I),
     "narrates rounds of work"),
]
CODE = sorted({*ROOT.glob("fiberpipe/**/*.py"), *ROOT.glob("tests/**/*.py"), *ROOT.glob("data-samples/**/*.py"),
               *(ROOT / "tools").glob("*.py")} - {Path(__file__).resolve()})


def test_code_and_tests_do_not_narrate():
    found = []
    for path in CODE:
        for n, line in enumerate(path.read_text().splitlines(), 1):
            for pattern, why in CODE_NARRATION:
                if pattern.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{n}: {why}: {line.strip()[:100]}")
    assert not found, "\n".join(found)


def test_code_narration_check_flags_an_issue_number_and_passes_a_fixture_scope():
    def flags(line):
        return [why for pattern, why in CODE_NARRATION if pattern.search(line)]
    assert flags("# the default since issue #5's third round")
    assert flags("Until 2026-11-22 a segment owned a point contact")
    assert flags("see docs/contact.md §12")
    assert not flags('@pytest.fixture(scope="session")')
    assert not flags("# small helpers shared by the stages")
    assert not flags("best of 12 rounds of 500 steps")


# Reference pages stay readable at a sitting: what is measured and checked, not how it was found.
PAGE_LINE_BUDGETS = {"benchmarks.md": 400, "contact.md": 500}


@pytest.mark.parametrize("name", sorted(PAGE_LINE_BUDGETS))
def test_reference_pages_keep_their_line_budget(name):
    lines = (DOCS / name).read_text().count("\n")
    assert lines <= PAGE_LINE_BUDGETS[name], f"docs/{name}: {lines} lines > {PAGE_LINE_BUDGETS[name]}"
