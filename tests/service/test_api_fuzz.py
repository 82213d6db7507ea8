"""The HTTP API fuzzed from openapi/openapi.json with schemathesis against a real server.

Every operation gets valid and invalid requests generated from the committed spec (bodies,
query and path parameters, headers), and every answer goes through all of schemathesis'
response checks (``--checks all``: no server error; status codes, media types, headers and
schemas as documented; schema-valid requests accepted and schema-violating ones refused).
The only findings allowed are the documented ones of ``scripts/api_fuzz.py`` (the longer,
seeded run with the stateful phase), each with its reason in docs/reliability.md.
"""

from __future__ import annotations

import re
import sys
from collections import Counter, defaultdict

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.core.failures import Failure, FailureGroup
from schemathesis.generation import GenerationMode
from service_helpers import KEY_A, KEYS, REPO, ServerProcess

sys.path.insert(0, str(REPO / "scripts"))
from api_fuzz import DOCUMENTED  # noqa: E402

SPEC = REPO / "openapi" / "openapi.json"
EXAMPLES = 30  # per operation; the whole module takes well under a minute

schema = schemathesis.openapi.from_path(SPEC)
schema.config.generation.update(modes=[GenerationMode.POSITIVE, GenerationMode.NEGATIVE])

# Answers by operation and status class, to show the fuzzing reached the success paths too.
ANSWERS: defaultdict[str, Counter] = defaultdict(Counter)
DOCUMENTED_SEEN: Counter = Counter()


def _undocumented(failures: list[Failure], case, response) -> list[Failure]:
    """The failures no entry of ``DOCUMENTED`` explains (matched on the check's code and the
    answer's text, as the script matches the CLI's report)."""
    left = []
    for failure in failures:
        # A binary answer (LAS, NPZ, PLY) has no text; its bytes are decoded leniently.
        body = response.content.decode("utf-8", "replace")
        text = (f"{failure.title}\n{failure.message}\nContent-Type: {case.media_type}\n"
                f"[{response.status_code}] {body}")
        why = next((w for code, pattern, w in DOCUMENTED
                    if code == failure.code and re.search(pattern, text, re.S)), None)
        if why is None:
            left.append(failure)
        else:
            DOCUMENTED_SEEN[failure.code] += 1
    return left


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
# derandomize: the same cases every run; scripts/api_fuzz.py explores further with seeds.
@settings(max_examples=EXAMPLES, deadline=None, database=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
def test_no_operation_answers_a_server_error(case, api_server):
    """Authenticated requests: any generated input ends in a documented, non-5xx answer
    (503 only as the documented, transient ``queue-full`` / ``not-ready``)."""
    response = case.call(base_url=api_server.url, headers=api_server.headers, timeout=60)
    ANSWERS[case.operation.label][response.status_code // 100] += 1
    try:
        case.validate_response(response, headers=api_server.headers)  # every check
    except FailureGroup as group:
        left = _undocumented(list(group.exceptions), case, response)
        if left:
            raise FailureGroup(left, group.message) from None
    except Failure as failure:
        if _undocumented([failure], case, response):
            raise


def test_fuzzing_reached_success_and_error_paths():
    """Runs after the fuzzing above (same module, defined later)."""
    for label in ("POST /v1/jobs", "POST /v1/curvature", "GET /v1/jobs"):
        assert ANSWERS[label][2] > 0 and ANSWERS[label][4] > 0, (label, ANSWERS[label])
    assert not any(counts[5] for counts in ANSWERS.values()), dict(ANSWERS)
    total = sum(sum(c.values()) for c in ANSWERS.values())
    print(f"schemathesis: {total} requests over {len(ANSWERS)} operations: "
          + ", ".join(f"{k} {dict(v)}" for k, v in sorted(ANSWERS.items()))
          + f"; documented findings {dict(DOCUMENTED_SEEN)}")
