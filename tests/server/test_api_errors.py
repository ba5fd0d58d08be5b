"""Requests that were HTTP 500s, and body-level errors in one line that says what was wanted.

The oracles: each status is the declared 4xx, each ``detail`` one line naming the
problem; the JSON decode position is checked against :func:`json.loads` of the same body.
"""

from __future__ import annotations

import json

import pytest
from server_helpers import AUTH, walk


def _one_line(resp) -> str:
    detail = resp.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail, detail
    return detail


@pytest.mark.parametrize(
    "path",
    [
        "/console/app.mjs%00.png",
        "/console/%00",
        "/console/main.mjs%00",
        "/vendor/ol/ol.js%00",
        "/vendor/swagger-ui/swagger-ui.css%00",
    ],
)
def test_a_nul_byte_in_a_static_path_is_404(ro_client, path):
    resp = ro_client.get(path)
    assert resp.status_code == 404, resp.text
    _one_line(resp)


@pytest.mark.parametrize(
    ("path", "name"),
    [
        ("/api/detections?after_id=1000000000000000000000000000000", "after_id"),
        ("/api/detections?after_id=9223372036854775808", "after_id"),
    ],
)
def test_an_id_beyond_sqlite_integers_is_422(ro_client, path, name):
    resp = ro_client.get(path, headers=AUTH)
    assert resp.status_code == 422, resp.text
    assert name in _one_line(resp)


def test_the_largest_sqlite_integer_is_still_accepted(ro_client):
    resp = ro_client.get("/api/detections?after_id=9223372036854775807", headers=AUTH)
    assert resp.status_code == 200 and resp.json() == []
    assert ro_client.get("/api/tracks/9223372036854775807", headers=AUTH).status_code == 404
    # A track id of any size is looked up and not found (the store bounds it itself).
    assert ro_client.get(f"/api/tracks/{10**30}", headers=AUTH).status_code == 404


def test_a_bare_list_body_says_an_object_with_detections_was_expected(ro_client):
    resp = ro_client.post("/api/detections", json=walk(n=2), headers=AUTH)
    assert resp.status_code == 422
    detail = _one_line(resp)
    assert detail == "request body: expected a JSON object with a 'detections' list, got a list"
    assert "Input should be" not in detail


def test_geolocate_names_each_required_field(ro_client):
    resp = ro_client.post("/api/geolocate", json="cam1", headers=AUTH)
    assert resp.status_code == 422
    assert _one_line(resp) == (
        "request body: expected a JSON object with a 'sensor' string, a 'u' number and a"
        " 'v' number, got a string"
    )


def test_a_missing_body_says_what_was_expected(ro_client):
    resp = ro_client.post("/api/detections", headers={**AUTH, "content-type": "application/json"})
    assert resp.status_code == 422
    assert _one_line(resp) == (
        "request body is missing: expected a JSON object with a 'detections' list"
    )


def test_a_json_decode_error_gives_its_line_column_and_position(ro_client):
    body = '{"detections": [\n  {"t": 1, "sensor": "cam1",}\n]}'
    with pytest.raises(json.JSONDecodeError) as want:
        json.loads(body)
    resp = ro_client.post(
        "/api/detections", content=body, headers={**AUTH, "content-type": "application/json"}
    )
    assert resp.status_code == 422
    detail = _one_line(resp)
    e = want.value
    assert detail == (
        f"request body is not valid JSON: {e.msg} at line {e.lineno} column {e.colno}"
        f" (character {e.pos})"
    )


def test_422_bodies_match_the_documented_schema(ro_client):
    schema = ro_client.app.openapi()
    op = schema["paths"]["/api/detections"]["post"]
    ref = op["responses"]["422"]["content"]["application/json"]["schema"]["$ref"]
    model = schema["components"]["schemas"][ref.rsplit("/", 1)[1]]
    assert model["properties"]["detail"]["type"] == "string"
    resp = ro_client.post("/api/detections", json=[], headers=AUTH)
    assert set(resp.json()) <= set(model["properties"])


def test_the_operator_token_is_a_security_scheme(ro_client):
    schema = ro_client.app.openapi()
    scheme = schema["components"]["securitySchemes"]["operatorToken"]
    assert scheme == {**scheme, "type": "http", "scheme": "bearer"}
    post = schema["paths"]["/api/detections"]["post"]
    assert post["security"] == [{"operatorToken": []}]
    assert "401" in post["responses"]
    assert "security" not in schema["paths"]["/api/health"]["get"]


def test_a_400_digit_time_is_a_skipped_record_not_a_500(ro_client):
    bad = {"t": int("9" * 400), "sensor": "cam1", "bbox": [500, 480, 540, 520], "class": "human"}
    resp = ro_client.post("/api/detections", json={"detections": [bad]}, headers=AUTH)
    assert resp.status_code == 200, resp.text
    ack = resp.json()
    assert (
        ack["accepted"] == 0 and ack["skipped"] == 1 and "400 digits" in ack["issues"][0]["message"]
    )


def test_a_body_that_is_not_utf8_is_422_saying_so(ro_client):
    resp = ro_client.post(
        "/api/detections", content=b'{"detections": ["\xff\xfe"]}',
        headers={**AUTH, "content-type": "application/json"},
    )  # fmt: skip
    assert resp.status_code == 422
    assert _one_line(resp).startswith("request body is not valid JSON: not UTF-8 text")
