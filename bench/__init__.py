"""`python -m bench`: the benchmark behind `make bench` (accuracy + held-out bodies + speed
+ HTTP load), writing ``reports/``. See docs/benchmarks.md.

Modules: :mod:`bench.edits` (problems, solving through the service engine),
:mod:`bench.metrics`, :mod:`bench.accuracy` (B1-B5, determinism, composition ablation),
:mod:`bench.heldout` (world-space edits on held-out bodies, the stress set),
:mod:`bench.speed`, :mod:`bench.http_load`, :mod:`bench.plots`, :mod:`bench.report`.
"""

import os

# one thread everywhere, before numpy / onnxruntime are imported by any bench module
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
