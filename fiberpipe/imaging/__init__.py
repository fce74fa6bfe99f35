"""Imaging stages: load a CT volume, segment it, skeletonize it, trace fiber mid-lines.

Array-level API (the CLI and the artifact layer wrap these):

- :func:`fiberpipe.imaging.io.load_volume`, :func:`fiberpipe.imaging.io.save_volume_tif`;
  the format readers in :mod:`fiberpipe.imaging.readers`
- :func:`fiberpipe.imaging.segment.segment`; slab by slab for large volumes,
  :func:`fiberpipe.imaging.segment_chunked.segment_chunked`
- :func:`fiberpipe.imaging.skeleton.skeletonize`
- :func:`fiberpipe.imaging.trace.trace`; fragments and gaps in :mod:`fiberpipe.imaging.fragments`
- :func:`fiberpipe.imaging.orientation.mask_orientation`, :func:`fiberpipe.imaging.orientation.fiber_orientation`
- :func:`fiberpipe.imaging.profile.fwhm_radius_vox`
- :mod:`fiberpipe.imaging.overlay` (pictures to check a tracing)
- :func:`fiberpipe.imaging.phantom.make_phantom`, :func:`fiberpipe.imaging.phantom.make_short_fiber_phantom`,
  :func:`fiberpipe.imaging.phantom.make_hard_phantom`, :func:`fiberpipe.imaging.phantom.render_polylines`
- :func:`fiberpipe.imaging.accuracy.trace_accuracy`, :func:`fiberpipe.imaging.accuracy.format_accuracy`
"""
