"""The benchmarks that ``fiberpipe bench`` runs (docs/benchmarks.md).

Each module runs on its own too, ``python -m fiberpipe.benchmarks.<name> [--out PAGE]``:
``bench_solver`` (element-steps per second), ``bench_contact`` (the contact pass per pair),
``bench_pyelastica`` (against PyElastica, the ``bench`` extra), ``bench_threads`` (two threads
against one) and ``bench_imaging`` (imaging stages' wall time and peak memory); ``scenes`` builds
their run-config scenes and loads saved states. The developer's profiles, A/B runs and one-off
measurements are scripts of the repository's ``benchmarks/`` folder."""
