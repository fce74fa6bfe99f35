"""Stage ``post``: ``simulation.h5`` -> ``post/`` (CSV, PNG, summary.json, report.md)."""

from fiberpipe.post.report import run_post

__all__ = ["run_post"]
