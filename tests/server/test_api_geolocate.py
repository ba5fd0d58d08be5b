from __future__ import annotations

import json

from server_helpers import AUTH

from demtrack.cli import main


def test_geolocate_matches_the_cli_json(ro_client, sample_site_dir, capsys):
    for sensor, u, v, rule in (
        ("cam1", 640, 500, "all"),
        ("cam3", 700, 400, "last"),
        ("cam2", 300, 600, "road"),
        ("cam1", 640, 0, "first"),
    ):
        assert (
            main(
                [
                    "geolocate",
                    "--site",
                    str(sample_site_dir),
                    "--sensor",
                    sensor,
                    "--pixel",
                    str(u),
                    str(v),
                    "--rule",
                    rule,
                    "--json",
                ]
            )
            == 0
        )
        cli = json.loads(capsys.readouterr().out)
        r = ro_client.post(
            "/api/geolocate", headers=AUTH, json={"sensor": sensor, "u": u, "v": v, "rule": rule}
        )
        assert r.status_code == 200
        assert r.json() == cli


def test_batch_equals_singles(ro_client):
    pixels = [[100.0, 600.0], [640.0, 500.0], [1200.0, 700.0]]
    r = ro_client.post(
        "/api/geolocate/batch",
        headers=AUTH,
        json={"sensor": "cam2", "pixels": pixels, "rule": "all"},
    )
    assert r.status_code == 200
    results = r.json()["results"]
    assert len(results) == 3
    for p, got in zip(pixels, results, strict=True):
        one = ro_client.post(
            "/api/geolocate", headers=AUTH, json={"sensor": "cam2", "u": p[0], "v": p[1]}
        ).json()
        assert got == one


def test_bad_input_is_a_clear_4xx(ro_client):
    cases = [
        ({"sensor": "cam1", "u": 5000, "v": 1}, 422, "outside"),
        ({"sensor": "nope", "u": 1, "v": 1}, 404, "unknown sensor"),
        ({"sensor": "cam1", "u": 1}, 422, "v"),
        ({"sensor": "cam1", "u": 1, "v": 1, "rule": "middle"}, 422, "rule"),
        ({"sensor": "cam1", "u": "x", "v": 1}, 422, "u"),
        ({"sensor": "cam1", "u": 1, "v": 1, "pixel_sigma_px": -1}, 422, "pixel_sigma_px"),
        ({"sensor": "cam1", "u": 1, "v": 1, "extra": 1}, 422, "extra"),
    ]
    for body, code, word in cases:
        r = ro_client.post("/api/geolocate", headers=AUTH, json=body)
        assert r.status_code == code, body
        assert word in r.json()["detail"], (body, r.json())
    for text in (
        '{"sensor": "cam1", "u": NaN, "v": 1}',
        '{"sensor": "cam1", "u": Infinity, "v": 1}',
        "not json",
        "[]",
        "",
    ):
        r = ro_client.post(
            "/api/geolocate", headers={**AUTH, "Content-Type": "application/json"}, content=text
        )
        assert r.status_code == 422, text
        assert r.json()["detail"]
    r = ro_client.post("/api/geolocate/batch", headers=AUTH, json={"sensor": "cam1", "pixels": []})
    assert r.status_code == 422
