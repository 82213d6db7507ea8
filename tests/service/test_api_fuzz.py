"""The HTTP API fuzzed from openapi/openapi.json with schemathesis against a real server.

Every operation gets valid and invalid requests generated from the committed spec (bodies,
query and path parameters, headers); no answer may be a server error, and every answer must
match what the spec documents (status codes, media types, response schemas).
"""

from __future__ import annotations

from collections import Counter, defaultdict

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.generation import GenerationMode
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)
from service_helpers import KEY_A, KEYS, REPO, ServerProcess

SPEC = REPO / "openapi" / "openapi.json"
EXAMPLES = 60  # per operation; the whole module takes about a minute

schema = schemathesis.openapi.from_path(SPEC)
schema.config.generation.update(modes=[GenerationMode.POSITIVE, GenerationMode.NEGATIVE])

# Answers by operation and status class, to show the fuzzing reached the success paths too.
ANSWERS: defaultdict[str, Counter] = defaultdict(Counter)
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance,
          response_schema_conformance]


@pytest.fixture(scope="module")
def api_server(tmp_path_factory):
    root = tmp_path_factory.mktemp("api-fuzz")
    # Small limits so generated uploads stay cheap; keys on, as in production.
    proc = ServerProcess(root / "data", root / "server.log", api_key=KEY_A, api_keys=KEYS,
                         sync_max_points=2000, max_upload_bytes=1 << 20,
                         max_json_bytes=1 << 20, job_time_limit_seconds=20).start()
    yield proc
    proc.stop()


@schema.parametrize()
@settings(max_examples=EXAMPLES, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
def test_no_operation_answers_a_server_error(case, api_server):
    """Authenticated requests: any generated input ends in a documented, non-5xx answer
    (503 only as the documented, transient ``queue-full`` / ``not-ready``)."""
    response = case.call(base_url=api_server.url, headers=api_server.headers, timeout=60)
    ANSWERS[case.operation.label][response.status_code // 100] += 1
    case.validate_response(response, checks=CHECKS,
                           headers=api_server.headers)


def test_fuzzing_reached_success_and_error_paths():
    """Runs after the fuzzing above (same module, defined later)."""
    for label in ("POST /v1/jobs", "POST /v1/curvature", "GET /v1/jobs"):
        assert ANSWERS[label][2] > 0 and ANSWERS[label][4] > 0, (label, ANSWERS[label])
    assert not any(counts[5] for counts in ANSWERS.values()), dict(ANSWERS)
    total = sum(sum(c.values()) for c in ANSWERS.values())
    print(f"schemathesis: {total} requests over {len(ANSWERS)} operations: "
          + ", ".join(f"{k} {dict(v)}" for k, v in sorted(ANSWERS.items())))
