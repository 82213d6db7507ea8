"""API keys: 401 without a valid key, jobs isolated per key, keys kept hashed, and the service
refusing to listen beyond loopback without keys."""

from __future__ import annotations

import contextlib
import os
import re
import sqlite3
import subprocess
import sys

import pytest
from service_helpers import KEY_A, KEY_B, REPO, bearer, sphere, wait_for_job

from service import auth
from service.auth import KeyConfigError, KeyRing, check_exposure, key_digest, load_keyring
from service.settings import Settings

PROBLEM = "application/problem+json"


def submit(client, key: str, n: int = 60) -> dict:
    response = client.post("/v1/jobs", json={"points": sphere(n).tolist()}, headers=bearer(key))
    assert response.status_code == 202, response.text
    return response.json()


@contextlib.contextmanager
def open_service(client):
    """The running app as if started without keys."""
    original = client.app.state.keyring
    client.app.state.keyring = KeyRing()
    try:
        yield
    finally:
        client.app.state.keyring = original


# -- requests ----------------------------------------------------------------------------------

@pytest.mark.parametrize("headers", [
    {"Authorization": ""},
    {"Authorization": "Bearer"},
    {"Authorization": f"Basic {KEY_A}"},
])
def test_missing_key_is_401_with_a_bearer_challenge(client, headers):
    for response in (client.get("/v1/jobs", headers=headers),
                     client.post("/v1/jobs", json={"points": sphere(20).tolist()},
                                 headers=headers),
                     client.post("/v1/curvature", json={"points": sphere(20).tolist()},
                                 headers=headers)):
        assert response.status_code == 401, response.text
        assert response.headers["content-type"] == PROBLEM
        assert response.headers["www-authenticate"] == 'Bearer realm="curvature"'
        body = response.json()
        assert body["type"] == "/problems/unauthorized"
        assert "Authorization: Bearer" in body["detail"]


@pytest.mark.parametrize("token", [KEY_A + "x", KEY_A[:-1], "x" * 5000, "ümlaut-key-0123456789"])
def test_wrong_key_is_401_invalid_token(client, token):
    response = client.get("/v1/jobs", headers={
        "Authorization": f"Bearer {token}".encode("latin-1")})
    assert response.status_code == 401
    assert response.headers["www-authenticate"] == \
        'Bearer realm="curvature", error="invalid_token"'
    assert token not in response.text  # the presented key is never echoed


def test_public_endpoints_need_no_key(client):
    anonymous = {"Authorization": ""}
    for path in ("/healthz", "/readyz", "/metrics", "/v1/methods", "/problems",
                 "/problems/unauthorized", "/openapi.json"):
        assert client.get(path, headers=anonymous).status_code == 200, path


def test_jobs_are_isolated_per_key(client):
    mine = wait_for_job(client, submit(client, KEY_A)["id"])
    theirs = submit(client, KEY_B)
    other = bearer(KEY_B)
    # Key B sees key A's job exactly as a job that does not exist.
    for response in (client.get(f"/v1/jobs/{mine['id']}", headers=other),
                     client.get(f"/v1/jobs/{mine['id']}/result", headers=other),
                     client.delete(f"/v1/jobs/{mine['id']}", headers=other)):
        assert response.status_code == 404, response.text
        assert response.json()["type"] == "/problems/job-not-found"
        assert response.json()["detail"] == f"no job with id {mine['id']!r}"
    listed_b = client.get("/v1/jobs", params={"limit": 200}, headers=other).json()["items"]
    assert mine["id"] not in {j["id"] for j in listed_b}
    assert theirs["id"] in {j["id"] for j in listed_b}
    listed_a = client.get("/v1/jobs", params={"limit": 200}).json()["items"]
    assert theirs["id"] not in {j["id"] for j in listed_a}
    # The failed DELETE did not touch the job; its owner still gets it.
    assert client.get(f"/v1/jobs/{mine['id']}/result").status_code == 200
    assert client.get(f"/v1/jobs/{theirs['id']}").status_code == 404


def _read_if_present(path) -> bytes:
    # SQLite removes its -wal/-shm files when the last connection closes, which can happen
    # between the glob and the read.
    try:
        return path.read_bytes()
    except FileNotFoundError:
        return b""


def test_the_store_holds_digests_never_keys(client):
    job = submit(client, KEY_B)
    db = client.app.state.settings.db_path
    conn = sqlite3.connect(db)
    owner = conn.execute("SELECT owner FROM jobs WHERE id = ?", (job["id"],)).fetchone()[0]
    conn.close()
    assert owner == key_digest(KEY_B) and re.fullmatch(r"[0-9a-f]{64}", owner)
    raw = b"".join(_read_if_present(p) for p in db.parent.glob("jobs.sqlite3*"))
    for key in (KEY_A, KEY_B):
        assert key.encode() not in raw
    # Nor does the running app keep them: only the digests.
    assert client.app.state.settings.api_keys is None
    assert set(client.app.state.keyring.digests) == {key_digest(KEY_A), key_digest(KEY_B)}


def test_without_keys_everyone_is_the_anonymous_owner(client):
    with open_service(client):
        first = client.post("/v1/jobs", json={"points": sphere(40).tolist()},
                            headers={"Authorization": ""})
        assert first.status_code == 202, first.text
        # Any header, or none, is the same caller.
        listed = client.get("/v1/jobs", headers={"Authorization": "Bearer whatever"}).json()
        assert first.json()["id"] in {j["id"] for j in listed["items"]}
    db = client.app.state.settings.db_path
    conn = sqlite3.connect(db)
    owner = conn.execute("SELECT owner FROM jobs WHERE id = ?", (first.json()["id"],)).fetchone()
    conn.close()
    assert owner[0] == auth.ANONYMOUS
    # Keys back on: the anonymous job is nobody's.
    assert client.get(f"/v1/jobs/{first.json()['id']}").status_code == 404


# -- the key ring ------------------------------------------------------------------------------

def test_every_configured_digest_is_compared(monkeypatch):
    calls = []
    real = auth.hmac.compare_digest

    def counting(a, b):
        calls.append(b)
        return real(a, b)

    ring = KeyRing(tuple(sorted(key_digest(k) for k in (KEY_A, KEY_B, "c" * 20, "d" * 20))))
    monkeypatch.setattr(auth.hmac, "compare_digest", counting)
    for token, expected in ((KEY_A, key_digest(KEY_A)), ("unknown-key-0123456789", None)):
        calls.clear()
        assert ring.owner_of(token) == expected
        assert sorted(calls) == list(ring.digests)  # all of them, whichever matched


def test_keys_from_variable_and_file(tmp_path):
    path = tmp_path / "keys.txt"
    path.write_text(f"# operators\n\n  {KEY_B}  \n{'e' * 32}\n", encoding="utf-8")
    ring = load_keyring(Settings(api_keys=f" {KEY_A} ,, ", api_keys_file=path))
    assert set(ring.digests) == {key_digest(k) for k in (KEY_A, KEY_B, "e" * 32)}
    assert not load_keyring(Settings(api_keys=None)).enabled
    assert not load_keyring(Settings(api_keys=" , ")).enabled


@pytest.mark.parametrize(("content", "match"), [
    (None, "cannot read"),
    ("# only a comment\n\n", "no key"),
    ("short\n", "line 1: an API key must be 16 to 512 characters"),
    (f"{KEY_A}\nhas space in it 0123456789\n", "line 2"),
])
def test_unusable_key_files_are_refused_without_echoing_keys(tmp_path, content, match):
    path = tmp_path / "keys.txt"
    if content is not None:
        path.write_text(content, encoding="utf-8")
    with pytest.raises(KeyConfigError, match=match) as info:
        load_keyring(Settings(api_keys_file=path))
    assert "0123456789" not in str(info.value) and "short\n" not in str(info.value)


def test_bad_key_in_the_variable_names_its_position():
    with pytest.raises(KeyConfigError, match="entry 2") as info:
        load_keyring(Settings(api_keys=f"{KEY_A},too-short"))
    assert "too-short" not in str(info.value)


@pytest.mark.parametrize(("host", "keys", "allow_open", "refused"), [
    ("127.0.0.1", None, False, False),
    ("127.0.0.2", None, False, False),
    ("::1", None, False, False),
    ("localhost", None, False, False),
    ("0.0.0.0", None, False, True),
    ("::", None, False, True),
    ("192.168.1.10", None, False, True),
    ("example.org", None, False, True),
    ("0.0.0.0", KEY_A, False, False),
    ("0.0.0.0", None, True, False),
])
def test_exposure_rule(host, keys, allow_open, refused):
    settings = Settings(host=host, api_keys=keys, allow_open=allow_open)
    reason = check_exposure(settings, load_keyring(settings))
    assert (reason is not None) == refused
    if refused:
        assert host in reason and "CURVATURE_API_KEYS" in reason
        assert "CURVATURE_ALLOW_OPEN" in reason


# -- starting the server -----------------------------------------------------------------------

def dockerfile_env() -> dict[str, str]:
    """The ENV of the Dockerfile's runtime stage."""
    text = (REPO / "Dockerfile").read_text(encoding="utf-8")
    runtime = text.split("AS runtime", 1)[1]
    env = {}
    for block in re.findall(r"^ENV (.*?)(?<!\\)$", runtime, flags=re.M | re.S):
        for name, value in re.findall(r"(\w+)=(\S+)", block):
            env[name] = value
    return env


def run_service(tmp_path, **env) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("CURVATURE_")}
    clean.update({"CURVATURE_DATA_DIR": str(tmp_path / "data"), "CURVATURE_PORT": "9"})
    clean.update(env)
    return subprocess.run([sys.executable, "-m", "service"], cwd=REPO, env=clean,
                          capture_output=True, text=True, timeout=60)


def test_the_image_refuses_to_start_open(tmp_path):
    env = dockerfile_env()
    assert env["CURVATURE_HOST"] == "0.0.0.0"
    assert "CURVATURE_ALLOW_OPEN" not in env and "CURVATURE_API_KEYS" not in env
    env = {k: v for k, v in env.items() if k.startswith("CURVATURE_")}
    env["CURVATURE_DATA_DIR"] = str(tmp_path / "data")
    out = run_service(tmp_path, **env)
    assert out.returncode == 78, out.stderr
    assert "refusing to listen on 0.0.0.0 without API keys" in out.stderr
    assert "CURVATURE_ALLOW_OPEN=true" in out.stderr
    assert not (tmp_path / "data").exists()  # refused before touching anything


def test_unreadable_key_file_stops_the_start(tmp_path):
    out = run_service(tmp_path, CURVATURE_HOST="127.0.0.1",
                      CURVATURE_API_KEYS_FILE=str(tmp_path / "missing.txt"))
    assert out.returncode == 78
    assert "cannot load the API keys" in out.stderr and "missing.txt" in out.stderr
