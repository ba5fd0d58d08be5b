"""docs/site-format.md's worked real-site example, executed as written.

The commands of the section's ``console`` blocks run in order in a temporary folder on the
raw inputs that ``docs/examples/make_real_site_inputs.py`` writes; each output must match
the one the doc shows (text exactly, numbers to within 2 % + 0.02), and the final geolocation
must land on the true ground point of ``truth.json`` (computed by the generator without
demtrack: an analytic terrain and an independent pinhole projection through ECEF).
"""

from __future__ import annotations

import importlib.util
import json
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest
from pyproj import Geod

from demtrack.cli import main
from demtrack.core.site.folder import load_site

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "site-format.md"
GENERATOR = ROOT / "docs" / "examples" / "make_real_site_inputs.py"
SECTION = "## Worked example: a real site from raw inputs"
COMMANDS = [
    "build-dem", "import-dem", "import-ortho", "import-roads", "add-camera", "geolocate",
    "calibrate", "geolocate",
]  # fmt: skip
H_TOL_M, V_TOL_M = 0.25, 0.10  # the doc states these
NUM_RTOL, NUM_ATOL = 0.02, 0.02
# A number: not part of a name (gcp08, 17N, EPSG:32617); thousands may be grouped.
_NUM = re.compile(r"(?<![\w.:])[-+]?(?:\d{1,3}(?:,\d{3})+|\d+)(?:\.\d+)?(?!\w)")
_HIT = re.compile(r"^\s*hit \d+\*.*\| lat (\S+)\s+lon (\S+)\s+h\s+(\S+) m")
GEOD = Geod(ellps="WGS84")


@dataclass
class Step:
    argv: list[str]
    expected: list[str]


def worked_example_steps(text: str) -> list[Step]:
    """The ``$ `` commands (with ``\\`` continuations) of the section's console blocks,
    each with the output lines shown after it."""
    start = text.index(SECTION)
    end = text.find("\n## ", start + len(SECTION))
    section = text[start : end if end >= 0 else len(text)]
    steps: list[Step] = []
    for block in re.findall(r"```console\n(.*?)```", section, flags=re.S):
        lines = block.splitlines()
        k = 0
        while k < len(lines):
            line = lines[k]
            if not line.startswith("$ "):
                if not steps:
                    raise AssertionError(f"output before any command: {line!r}")
                steps[-1].expected.append(line)
                k += 1
                continue
            cmd = line[2:]
            while cmd.endswith("\\"):
                k += 1
                cmd = cmd[:-1] + " " + lines[k].strip()
            steps.append(Step(shlex.split(cmd), []))
            k += 1
    return steps


def _numbers(line: str) -> tuple[list[str], list[float]]:
    skeleton = _NUM.sub("#", line).split()
    values = [float(m.replace(",", "")) for m in _NUM.findall(line)]
    return skeleton, values


def output_mismatch(actual: str, expected: list[str]) -> str | None:
    """Why ``actual`` differs from the doc's lines (text exactly, numbers within
    ``NUM_RTOL`` relative plus ``NUM_ATOL``), or None when it matches."""
    got = [ln.rstrip() for ln in actual.rstrip("\n").splitlines()]
    want = [ln.rstrip() for ln in expected]
    if len(got) != len(want):
        return f"{len(got)} output lines, the doc shows {len(want)}"
    for k, (g, w) in enumerate(zip(got, want, strict=True)):
        (gs, gv), (ws, wv) = _numbers(g), _numbers(w)
        if gs != ws:
            return f"line {k + 1}: text differs:\n  got:  {g}\n  doc:  {w}"
        for a, b in zip(gv, wv, strict=True):
            if abs(a - b) > NUM_ATOL + NUM_RTOL * max(abs(a), abs(b)):
                return f"line {k + 1}: {a:g} where the doc shows {b:g}:\n  got:  {g}\n  doc:  {w}"
    return None


def _generator():
    spec = importlib.util.spec_from_file_location("make_real_site_inputs", GENERATOR)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _hit(out: str) -> tuple[float, float, float]:
    for line in out.splitlines():
        m = _HIT.match(line)
        if m:
            return tuple(float(x) for x in m.groups())
    raise AssertionError(f"no selected terrain hit in:\n{out}")


def _error_m(hit: tuple[float, float, float], target: dict) -> tuple[float, float]:
    lat, lon, h = hit
    _, _, d = GEOD.inv(target["lon_deg"], target["lat_deg"], lon, lat)
    return d, h - target["h_m"]


# ------------------------------------------------------------------ the comparison itself


def test_output_comparison_flags_changed_text_and_numbers():
    doc = ["x: 300x300 cells of 1.0 m from 265,106 points; 93.5 % hold points",
           "  gcp08   -27.58   +6.39  OUTLIER, excluded"]  # fmt: skip
    assert output_mismatch("\n".join(doc) + "\n", doc) is None
    near = doc[0].replace("265,106", "265,200")
    assert output_mismatch("\n".join([near, doc[1]]), doc) is None
    far = doc[0].replace("265,106", "285,106")
    assert "285106 where the doc shows 265106" in output_mismatch("\n".join([far, doc[1]]), doc)
    worded = doc[1].replace("excluded", "kept")
    assert "text differs" in output_mismatch("\n".join([doc[0], worded]), doc)
    assert "output lines" in output_mismatch(doc[0], doc)
    # Digits inside names are text, not numbers.
    assert output_mismatch("gcp09 EPSG:32617 zone 17N", ["gcp09 EPSG:32617 zone 17N"]) is None
    assert output_mismatch("gcp19", ["gcp09"]) is not None


def test_steps_are_parsed_with_continuations_and_outputs():
    text = (
        f'{SECTION}\n\n```console\n$ demtrack a --x 1 \\\n      --y "two words"\nout 1\n'
        "$ demtrack b\n```\n\n## Next\n```console\n$ demtrack c\n```\n"
    )
    steps = worked_example_steps(text)
    assert [s.argv for s in steps] == [["demtrack", "a", "--x", "1", "--y", "two words"],
                                       ["demtrack", "b"]]  # fmt: skip
    assert steps[0].expected == ["out 1"] and steps[1].expected == []


# ------------------------------------------------------------------ the worked example


def test_worked_example_runs_as_written_and_geolocates_the_true_point(
    tmp_path, monkeypatch, capsys
):
    steps = worked_example_steps(DOC.read_text(encoding="utf-8"))
    gen, *rest = steps
    assert gen.argv[0] == "python" and Path(gen.argv[1]).as_posix().endswith(
        "docs/examples/make_real_site_inputs.py"
    ), gen.argv
    assert [s.argv[0] for s in rest] == ["demtrack"] * len(rest)
    assert [s.argv[1] for s in rest] == COMMANDS
    assert "--ground-only" in rest[0].argv

    monkeypatch.chdir(tmp_path)
    outputs = []
    for step in steps:
        if step is gen:
            status = _generator().main(step.argv[2:])
        else:
            status = main(step.argv[1:])
        out, err = capsys.readouterr()
        shown = " ".join(step.argv)
        assert status == 0, f"$ {shown}\n{err}"
        problem = output_mismatch(out, step.expected)
        assert problem is None, f"$ {shown}\n{problem}\nactual output:\n{out}"
        outputs.append(out)

    truth = json.loads((tmp_path / "raw" / "truth.json").read_text())
    target = truth["target"]
    # The doc's commands say what the survey and the answer key say.
    add_camera = rest[COMMANDS.index("add-camera")].argv
    k = add_camera.index("--position")
    assert [float(x) for x in add_camera[k + 1 : k + 4]] == truth["survey"]["position"]
    assert float(add_camera[add_camera.index("--az") + 1]) == truth["survey"]["grid_azimuth_deg"]
    assert float(add_camera[add_camera.index("--tilt") + 1]) == truth["survey"]["tilt_deg"]
    for step in (rest[-3], rest[-1]):
        k = step.argv.index("--pixel")
        assert [float(x) for x in step.argv[k + 1 : k + 3]] == target["pixel"]

    # With the surveyed pose the pixel lands metres away; calibrated, on the point.
    before_m, _ = _error_m(_hit(outputs[-3]), target)
    d_m, dh_m = _error_m(_hit(outputs[-1]), target)
    assert before_m > 2.0
    assert d_m < H_TOL_M and abs(dh_m) < V_TOL_M, (d_m, dh_m)
    fitted = load_site(tmp_path / "mysite").sensor("cam1").camera.azimuth_tilt_roll_deg()
    assert fitted[0] == pytest.approx(truth["camera"]["az_true_deg"], abs=0.02)
    assert fitted[1] == pytest.approx(truth["camera"]["tilt_deg"], abs=0.02)

    # The prose's truth and error figures are the ones measured.
    text = DOC.read_text(encoding="utf-8")
    m = re.search(r"is at lat (\S+) lon (\S+), h (\S+) m \(ellipsoidal\): the hit is (\d+) cm "
                  r"from it\s+horizontally and (\d+) mm in height", text)  # fmt: skip
    assert m, "the worked example no longer states the true point and the error"
    lat, lon, h, cm, mm = (float(x) for x in m.groups())
    assert abs(lat - target["lat_deg"]) < 1e-8 and abs(lon - target["lon_deg"]) < 1e-8
    assert h == pytest.approx(target["h_m"], abs=1e-3)
    assert abs(cm - 100 * d_m) < 3.0 and abs(mm - 1000 * abs(dh_m)) < 10.0
    assert f"requires {H_TOL_M:g} m and {V_TOL_M:.2f} m" in " ".join(text.split())
