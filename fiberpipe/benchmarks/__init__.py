"""The benchmarks that ``fiberpipe bench`` runs (docs/benchmarks.md).

Each module runs on its own too, ``python -m fiberpipe.benchmarks.<name> [--out PAGE]``:
``bench_solver`` (element-steps per second), ``bench_contact`` (the contact pass per pair),
``bench_effects`` (what each effect costs), ``bench_pyelastica`` (against PyElastica, the
``bench`` extra) and ``bench_imaging`` (imaging stages' wall time and peak memory)."""
