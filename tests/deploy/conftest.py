"""Figures of the container check, printed after the run as ``SMOKE name=value`` lines
(by tests/conftest.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

K8S = Path(__file__).resolve().parents[2] / "deploy" / "k8s"

FIGURES: dict[str, str] = {}


@pytest.fixture(scope="session")
def figures() -> dict[str, str]:
    return FIGURES


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    """Each report of a test here carries the figures so far (``smoke_figures``): under
    pytest-xdist the process that prints the summary (tests/conftest.py) is not the one
    that ran the test."""
    report = yield
    if FIGURES:
        report.user_properties.append(("smoke_figures", dict(FIGURES)))
    return report


@pytest.fixture(scope="session")
def k8s() -> dict[str, dict[str, Any]]:
    """The Kubernetes manifests (deploy/k8s) by kind (one object of each)."""
    yaml = pytest.importorskip("yaml")
    docs: dict[str, dict[str, Any]] = {}
    for path in sorted(K8S.glob("*.yaml")):
        if path.name == "kustomization.yaml":
            continue
        for doc in yaml.safe_load_all(path.read_text()):
            if doc:
                assert doc["kind"] not in docs, f"two {doc['kind']} objects"
                docs[doc["kind"]] = doc
    assert {"Deployment", "Service", "HorizontalPodAutoscaler"} <= docs.keys(), docs.keys()
    return docs


def deployment_container(k8s: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The Deployment's one container."""
    (container,) = k8s["Deployment"]["spec"]["template"]["spec"]["containers"]
    return container
