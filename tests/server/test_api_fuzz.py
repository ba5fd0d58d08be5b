"""Schema fuzzing of the whole OpenAPI document (schemathesis), with the operator token.

Every operation gets at least 50 generated requests that fit its schema (positive) and
50 that break it (negative), sent in-process to the ASGI app (its lifespan started once,
on the sample site, a fresh database). The oracle is the OpenAPI document itself: no
response may be a server error, carry a status the operation does not declare, or have
a body that violates the declared schema of its status. Hypothesis is derandomised, so
each run sends the same requests.
"""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)
from server_helpers import AUTH, make_app

pytestmark = pytest.mark.timeout(600)

EXAMPLES = 50  # requests that fit the schema, per operation
NEGATIVE_EXAMPLES = 25  # requests that break it, per operation (each answered 4xx)
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_schema_conformance,
]


@pytest.fixture(scope="module")
def api_schema(
    sample_site_dir: Path, tmp_path_factory: pytest.TempPathFactory, module_store_kw: dict
) -> Any:
    # No live activity detectors: they cost time per ingest and are not what is fuzzed.
    app = make_app(
        sample_site_dir, tmp_path_factory.mktemp("fuzz"), events=False, **module_store_kw
    )
    return schemathesis.openapi.from_asgi("/openapi.json", app)


#: Whole-site coverage is computed afresh for every distinct range (seconds each, cached
#: per value): it is fuzzed on every other parameter with a short range. The range itself
#: is fuzzed on the per-sensor viewshed, which shares its validation.
FIXED_QUERY = {
    "GET /api/site/coverage.png": {"max_range_m": 30.0},
    "GET /api/site/coverage.json": {"max_range_m": 30.0},
}


def _fuzz(operation: Any, mode: schemathesis.GenerationMode) -> tuple[int, list[str]]:
    """Send the generated cases; the number sent and the failures seen.

    An operation without parameters has one distinct request: hypothesis stops after it,
    and it is sent again until ``EXAMPLES`` have gone.
    """
    sent = 0
    failures: list[str] = []
    fixed = FIXED_QUERY.get(operation.label)
    last: list[Any] = []

    @given(case=operation.as_strategy(generation_mode=mode, query=fixed))
    @settings(
        max_examples=EXAMPLES if mode.is_positive else NEGATIVE_EXAMPLES,
        deadline=None,
        derandomize=True,
        database=None,
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    def run(case: Any) -> None:
        last[:] = [case]
        send(case)

    def send(case: Any) -> None:
        nonlocal sent
        sent += 1
        try:
            response = case.call(headers=dict(AUTH))  # a copy: the call adds its own headers to it
        except Exception as exc:  # noqa: BLE001 - the app raised: a server error
            failures.append(f"{operation.label} [{mode.value}] raised {exc!r:.300}")
            return
        try:
            case.validate_response(response, checks=CHECKS)
        except (Exception, BaseExceptionGroup) as exc:  # noqa: BLE001 - reported below, all
            request = response.request
            lines = [x.strip() for x in str(exc).splitlines() if x.strip()]
            what = " | ".join(lines[1:4]) if len(lines) > 1 else (lines or [repr(exc)])[0]
            failures.append(
                f"{operation.label} [{mode.value}] {request.method} {request.url} ->"
                f" {response.status_code} {response.text[:160]!r}: {what}"
            )

    try:
        run()
    except Unsatisfiable:  # nothing to break: an operation without parameters or body
        if mode.is_positive:
            raise
    while mode.is_positive and last and sent < EXAMPLES:
        send(last[0])
    return sent, failures


def test_schema_fuzz_finds_no_server_error_and_no_schema_violation(api_schema: Any) -> None:
    operations = [result.ok() for result in api_schema.get_all_operations()]
    assert len(operations) >= 15, [op.label for op in operations]
    sent: Counter[str] = Counter()
    failures: list[str] = []
    timing: dict[str, float] = {}
    for operation in operations:
        t0 = time.perf_counter()
        for mode in (schemathesis.GenerationMode.POSITIVE, schemathesis.GenerationMode.NEGATIVE):
            n, found = _fuzz(operation, mode)
            sent[operation.label] += n
            failures += found
        timing[operation.label] = round(time.perf_counter() - t0, 1)
    print(f"fuzzed {len(operations)} operations, {sum(sent.values())} requests: {dict(sent)}")
    print(f"seconds per operation: {timing}")
    assert not failures, f"{len(failures)} failing responses of {sum(sent.values())}:\n" + (
        "\n".join(failures[:40])
    )
    few = {label: n for label, n in sent.items() if n < EXAMPLES}
    assert not few, f"operations fuzzed with fewer than {EXAMPLES} cases: {few}"
