"""The Kubernetes manifests under deploy/k8s: valid YAML, and consistent with the service."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from service.settings import Settings

yaml = pytest.importorskip("yaml")

K8S = Path(__file__).parents[2] / "deploy" / "k8s"


def manifests() -> dict[str, dict[str, Any]]:
    """Every document of every manifest, by kind."""
    documents = [d for p in sorted(K8S.glob("*.yaml")) for d in yaml.safe_load_all(p.read_text())]
    return {d["kind"]: d for d in documents}


def test_the_manifests_hold_a_deployment_a_service_and_an_autoscaler() -> None:
    assert set(manifests()) == {"Deployment", "Service", "HorizontalPodAutoscaler"}


def test_the_deployment_probes_the_health_routes_and_sets_known_settings() -> None:
    kinds = manifests()
    (container,) = kinds["Deployment"]["spec"]["template"]["spec"]["containers"]
    assert container["livenessProbe"]["httpGet"]["path"] == "/healthz"
    assert container["readinessProbe"]["httpGet"]["path"] == "/readyz"
    assert {"cpu", "memory"} <= set(container["resources"]["requests"])
    known = {f"SCHEDULER_{name.upper()}" for name in Settings.model_fields}
    names = {e["name"] for e in container["env"]}
    assert names <= known
    (token,) = [e for e in container["env"] if e["name"] == "SCHEDULER_API_TOKEN"]
    assert "secretKeyRef" in token["valueFrom"]
    port = next(e["value"] for e in container["env"] if e["name"] == "SCHEDULER_PORT")
    assert int(port) == container["ports"][0]["containerPort"]


def test_the_service_and_autoscaler_point_at_the_deployment() -> None:
    kinds = manifests()
    labels = kinds["Deployment"]["spec"]["template"]["metadata"]["labels"]
    assert kinds["Service"]["spec"]["selector"].items() <= labels.items()
    target = kinds["HorizontalPodAutoscaler"]["spec"]["scaleTargetRef"]
    assert (target["kind"], target["name"]) == (
        "Deployment",
        kinds["Deployment"]["metadata"]["name"],
    )
