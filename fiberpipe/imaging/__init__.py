"""Imaging stages: load a CT volume, segment it, skeletonize it, trace fiber mid-lines.

Array-level API (the CLI and the artifact layer wrap these):

- :func:`fiberpipe.imaging.io.load_volume`, :func:`fiberpipe.imaging.io.save_volume_tif`
- :func:`fiberpipe.imaging.segment.segment`
- :func:`fiberpipe.imaging.skeleton.skeletonize`
- :func:`fiberpipe.imaging.trace.trace`
- :func:`fiberpipe.imaging.phantom.make_phantom`, :func:`fiberpipe.imaging.phantom.render_polylines`
- :func:`fiberpipe.imaging.accuracy.trace_accuracy`, :func:`fiberpipe.imaging.accuracy.format_accuracy`
"""
