"""Property tests: no request body, however odd, makes the API answer 5xx."""

from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from server_helpers import AUTH

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
values = st.recursive(
    scalars,
    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=4),
    max_leaves=12,
)
record = st.fixed_dictionaries(
    {
        "t": scalars,
        "sensor": st.sampled_from(["cam1", "cam2", "x", ""]),
        "bbox": st.one_of(st.lists(st.floats(-100, 2000), min_size=0, max_size=5), values),
        "class": st.sampled_from(["vehicle", "human", "cat"]),
    },
    optional={"score": scalars, "local_id": values},
)
common = settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


@common
@given(
    body=st.one_of(
        values,
        st.fixed_dictionaries(
            {"detections": st.lists(st.one_of(record, values), max_size=6)},
            optional={"batch_key": values},
        ),
    )
)
def test_ingest_never_5xx(ro_client, body):
    r = ro_client.post(
        "/api/detections",
        headers={**AUTH, "Content-Type": "application/json"},
        content=json.dumps(body),
    )
    assert r.status_code < 500, r.text
    if r.status_code == 200:
        ack = r.json()
        assert ack["accepted"] + ack["skipped"] == ack["n_records"]


@common
@given(
    body=st.one_of(
        values,
        st.fixed_dictionaries(
            {"sensor": st.sampled_from(["cam1", "cam3", "nope"]), "u": scalars, "v": scalars},
            optional={"rule": st.sampled_from(["first", "road", "x"]), "pixel_sigma_px": scalars},
        ),
    )
)
def test_geolocate_never_5xx(ro_client, body):
    r = ro_client.post(
        "/api/geolocate",
        headers={**AUTH, "Content-Type": "application/json"},
        content=json.dumps(body),
    )
    assert r.status_code < 500, r.text


@common
@given(
    q=st.dictionaries(
        st.sampled_from(["t_from", "t_to", "class", "sensor", "bbox"]),
        st.text(max_size=12),
        max_size=4,
    )
)
def test_tracks_query_never_5xx(ro_client, q):
    assert ro_client.get("/api/tracks", params=q, headers=AUTH).status_code < 500
