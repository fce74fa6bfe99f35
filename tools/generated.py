"""Replace the generated section of a docs page, between its begin and end markers.

The text around the markers is the page's own (hand-written) prose; only the section between them
comes from data."""

from __future__ import annotations

from pathlib import Path


def replace_section(page: Path, begin: str, end: str, text: str) -> None:
    """Write ``text`` between the lines starting with ``begin`` and ``end`` in ``page`` (atomic)."""
    old = page.read_text()
    lines = old.splitlines(keepends=True)
    try:
        i = next(k for k, ln in enumerate(lines) if ln.startswith(begin))
        j = next(k for k, ln in enumerate(lines) if k > i and ln.startswith(end))
    except StopIteration:
        raise SystemExit(f"{page}: markers '{begin}' … '{end}' not found") from None
    new = "".join(lines[: i + 1]) + "\n" + text.strip("\n") + "\n\n" + "".join(lines[j:])
    tmp = page.with_suffix(page.suffix + ".tmp")
    tmp.write_text(new)
    tmp.replace(page)


def replace_marked(page: Path, begin: str, end: str, text: str) -> None:
    """Replace the span of ``page`` from ``begin`` through ``end`` with ``text``, which carries its own
    markers (atomic)."""
    doc = page.read_text()
    try:
        i, j = doc.index(begin), doc.index(end) + len(end)
    except ValueError:
        raise SystemExit(f"{page}: markers '{begin}' … '{end}' not found") from None
    tmp = page.with_suffix(page.suffix + ".tmp")
    tmp.write_text(doc[:i] + text + doc[j:])
    tmp.replace(page)


def run_cli(main, argv=None) -> int:
    """``main(argv)`` with a problem the user can fix (an ensemble none of whose seeds finished, bad
    input) as one line on stderr, as ``fiberpipe`` prints it; returns the exit code."""
    import sys

    from fiberpipe.errors import FiberpipeError

    try:
        return main(argv)
    except FiberpipeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
