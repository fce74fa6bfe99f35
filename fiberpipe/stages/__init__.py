"""One module per pipeline stage. A stage is a plain function: artifact paths in, artifact out.

Each stage function takes the validated :class:`~fiberpipe.config.Config`, the paths of its input
artifacts and of its output, and returns a dict of figures for ``summary.json``. The runner
(:mod:`fiberpipe.pipeline`) and the CLI are thin layers over these functions.
"""
