"""Benchmarks: the dataset registry (twins + recorded lab data), scoring, accuracy baselines, the speed
suite, the main job (``piezotwin run``) and the CLI (:mod:`benchmarks.cli`). Uses :mod:`sysid` and :mod:`twins`."""
