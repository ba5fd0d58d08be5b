"""The CLI's parsers load no heavy library; their copied names match the owners'."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest

from demtrack.commands import choices

#: Libraries that only a running command may load (each costs a second or more).
HEAVY = ("numba", "scipy", "rasterio", "shapely", "fastapi", "viser", "pyproj")


def loaded_modules(code: str) -> set[str]:
    """The top-level package names in ``sys.modules`` after ``code`` runs in a fresh process."""
    probe = f"{code}; import sys; print('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=120
    ).stdout
    return {name.split(".")[0] for name in out.split()}


@pytest.mark.parametrize(
    "code",
    [
        "import demtrack.cli",
        # Every parser registered, as --help and any command line do before a command runs.
        "from demtrack.cli import build_parser; build_parser()",
    ],
)
def test_cli_import_and_parsers_load_no_heavy_library(code):
    loaded = loaded_modules(code)
    assert "demtrack" in loaded  # the probe did import the CLI
    assert sorted(loaded.intersection(HEAVY)) == []


def test_the_probe_sees_a_heavy_import():
    # The check above can fail: importing the engine does load numba and pyproj.
    loaded = loaded_modules("import demtrack.core.site.folder")
    assert {"numba", "pyproj"} <= loaded


def test_copied_choices_match_their_owners():
    from demtrack.core.camera.gcp_calibration import DEFAULT_FREE, FREE_PARAMETERS, LOSSES
    from demtrack.core.camera.gcp_convert import GCP_FORMATS
    from demtrack.core.geolocation.geolocate import RULES
    from demtrack.core.site.folder import MANIFEST
    from demtrack.core.tracking import METHODS
    from demtrack.samplesite.activity_scenarios import ACTIVITY_CASES, DEFAULT_ACTIVITY_PARAMS
    from demtrack.samplesite.scenarios import SCENARIOS, ScenarioParams

    assert choices.TRACKING_METHODS == tuple(METHODS)
    assert choices.DEFAULT_METHOD in METHODS
    assert choices.GEOLOCATE_RULES == tuple(RULES)
    assert choices.MANIFEST == MANIFEST
    assert choices.SCENARIO_NAMES == tuple(sorted(SCENARIOS))
    from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS

    assert choices.REPLAY_NAMES == SAMPLE_SCENARIOS.names
    assert choices.ACTIVITY_CASE_NAMES == tuple(ACTIVITY_CASES)
    assert choices.ACTIVITY_SEED == DEFAULT_ACTIVITY_PARAMS.seed
    assert choices.FREE_PARAMETERS == tuple(FREE_PARAMETERS)
    assert choices.DEFAULT_FREE == tuple(DEFAULT_FREE)
    assert choices.GCP_LOSSES == tuple(LOSSES)
    assert choices.GCP_FORMATS == tuple(GCP_FORMATS)
    defaults = dataclasses.asdict(ScenarioParams())
    assert choices.SCENARIO_DEFAULTS == {k: defaults[k] for k in choices.SCENARIO_DEFAULTS}


def test_parser_choices_and_defaults_are_the_owners():
    from demtrack.cli import build_parser
    from demtrack.core.tracking import METHODS
    from demtrack.samplesite.scenarios import ScenarioParams

    parser = build_parser()
    args = parser.parse_args(["scenario", "--name", "pedestrians", "-o", "x.csv"])
    d = ScenarioParams()
    assert (args.noise_px, args.p_miss, args.false_alarms, args.seed) == (
        d.noise_px,
        d.p_miss,
        d.false_alarm_rate,
        d.seed,
    )
    for method in METHODS:
        args = parser.parse_args(["track", "--detections", "d", "-o", "t.csv", "--method", method])
        assert args.method == method
