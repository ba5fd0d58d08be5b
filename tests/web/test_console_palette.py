"""One palette (issue 26, item 10): every colour one meaning, each camera its own colour.

The palette is ``web/console/palette.mjs``; the 3D scene's copy is
``server/scene3d/style.py``. Oracles: CIE76 colour differences computed here (sRGB ->
CIE Lab, D65) between every pair of meanings, the Python copy, and the colours the page
really draws with (the OpenLayers styles of footprints, sensors and viewsheds, the
camera panels' colour) read back from Chromium.
"""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest
from web_helpers import REPO, open_console

from demtrack.server.scene3d import style

pytestmark = pytest.mark.timeout(300)

PALETTE = REPO / "web" / "console" / "palette.mjs"
#: Two meanings closer than this (CIE76 delta E) could be taken for each other on the map.
MIN_DELTA_E = 25.0


def lab(hex_colour: str) -> np.ndarray:
    """CIE Lab (D65) of an sRGB ``#rrggbb``."""
    n = int(hex_colour.lstrip("#"), 16)
    c = np.array([(n >> 16) & 255, (n >> 8) & 255, n & 255]) / 255.0
    c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = m @ c / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16 / 116)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def js_const(name: str) -> str:
    m = re.search(rf"export const {name} = (.+?);\n", PALETTE.read_text(), re.S)
    assert m, name
    return m.group(1)


def js_hexes(name: str) -> list[str]:
    return re.findall(r'"(#[0-9a-fA-F]{6})"', js_const(name))


def test_every_meaning_has_its_own_colour():
    meanings = {
        "vehicle": js_hexes("CLASS_COLOURS")[0],
        "human": js_hexes("CLASS_COLOURS")[1],
        "selected": js_hexes("SELECTED_COLOUR")[0],
        "hit": js_hexes("HIT_COLOUR")[0],
        "blind spot": js_hexes("BLIND_COLOUR")[0],
        "road": js_hexes("ROAD_COLOUR")[0],
        **{
            f"event {k}": v
            for k, v in zip(
                ("confirmed", "ended", "handoff", "activity"),
                js_hexes("EVENT_PALETTE"),
                strict=False,
            )
        },  # fmt: skip
        **{f"camera {k + 1}": c for k, c in enumerate(js_hexes("SENSOR_COLOURS"))},
    }
    assert len(js_hexes("SENSOR_COLOURS")) >= 3
    close = [
        (a, b, round(float(np.linalg.norm(lab(meanings[a]) - lab(meanings[b]))), 1))
        for a, b in itertools.combinations(meanings, 2)
        if np.linalg.norm(lab(meanings[a]) - lab(meanings[b])) < MIN_DELTA_E
    ]
    assert close == []


def test_the_3d_scene_uses_the_same_colours():
    assert style.SENSOR_COLOURS == tuple(js_hexes("SENSOR_COLOURS"))
    vehicle, human = js_hexes("CLASS_COLOURS")
    assert style.class_colour("vehicle") == style.hex_colour(vehicle) == (255, 122, 26)
    assert style.class_colour("human") == style.hex_colour(human)
    assert style.SELECTED_COLOUR == js_hexes("SELECTED_COLOUR")[0]
    assert style.HIT_COLOUR == js_hexes("HIT_COLOUR")[0]
    for k, c in enumerate(js_hexes("SENSOR_COLOURS")):
        assert style.sensor_colour(k) == style.hex_colour(c)


def rgb_of(css: str) -> tuple[int, int, int]:
    """``#rrggbb`` or ``rgb(a)(r,g,b[,a])`` as (r, g, b)."""
    if css.startswith("#"):
        return style.hex_colour(css)
    r, g, b = (int(float(x)) for x in re.findall(r"[\d.]+", css)[:3])
    return r, g, b


def test_each_camera_is_drawn_in_its_own_colour_everywhere(page, fed_server):
    open_console(page, fed_server)
    cams = js_hexes("SENSOR_COLOURS")
    drawn = page.evaluate(
        """async () => {
        const m = window.demtrack.map;
        const style = (layer, f) => {
          const s = layer.getStyleFunction()(f, 1);
          return Array.isArray(s) ? s[0] : s;
        };
        const out = {};
        for (const f of m.coverage.getSource().getFeatures()) {
          const s = style(m.coverage, f);
          (out[f.get('sensor')] ||= {}).footprint = s.getStroke().getColor();
        }
        for (const f of m.sensors.getSource().getFeatures()) {
          out[f.get('sensor')].symbol = style(m.sensors, f).getImage().getFill().getColor();
        }
        for (const [id, p] of window.demtrack.ui.cams) {
          out[id].panel = getComputedStyle(p.root).getPropertyValue('--cam-colour').trim();
          out[id].swatch = getComputedStyle(p.root.querySelector('.cam-swatch')).backgroundColor;
        }
        const vis = window.demtrack.ui.vis;
        for (const id of Object.keys(out)) out[id].viewshed = vis.colours.get(id);
        return out;
        }"""
    )
    ids = sorted(drawn)
    assert len(ids) == 3
    for k, sid in enumerate(ids):
        want = style.hex_colour(cams[k])
        got = {what: rgb_of(c) for what, c in drawn[sid].items()}
        assert got == dict.fromkeys(drawn[sid], want), (sid, drawn[sid])
    # Three cameras, three colours: footprints no longer share one.
    assert len({drawn[s]["footprint"] for s in ids}) == 3
    # The legends name each camera in its colour.
    legend = page.evaluate(
        """[...document.querySelectorAll('#layers .legend span span.swatch')]
        .map((s) => [s.parentElement.textContent, getComputedStyle(s).backgroundColor])"""
    )
    for k, sid in enumerate(ids):
        r, g, b = style.hex_colour(cams[k])
        assert [sid, f"rgb({r}, {g}, {b})"] in legend  # "Sensors" legend
        assert [f"{sid} footprint", f"rgb({r}, {g}, {b})"] in legend  # "Camera footprints"
    assert page.record.errors == []
