"""`python -m bench`: the benchmark behind `make bench` (accuracy + speed + HTTP load).

Accuracy comes from :mod:`trainer.evaluate`; this package adds the in-process speed
measurements (:mod:`bench.speed`), the HTTP load test against a real uvicorn server on
loopback (:mod:`bench.http_load`), the speed plots and the full report (``reports/``).
"""
