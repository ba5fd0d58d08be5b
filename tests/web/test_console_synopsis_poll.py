"""The page asks for the server's synopsis less often when the server is slow to answer.

Live, the page polls ``/api/synopsis`` every 3 s, or every 20 times the last answer's
duration (at most 15 s), so a slow, busy server is not kept busier by the page. The
answers are slowed in the page itself (a ``fetch`` wrapper) while records stream in.
"""

from __future__ import annotations

import time

import pytest
from web_helpers import open_console, post_until

pytestmark = pytest.mark.timeout(600)

SLOW_MS = 700

SLOW_SYNOPSIS_JS = f"""
(() => {{
  const real = window.fetch.bind(window);
  window.fetch = async (input, init) => {{
    const resp = await real(input, init);
    const url = typeof input === 'string' ? input : input.url;
    if (url.includes('/api/synopsis')) {{
      window.synopsisCalls = (window.synopsisCalls || 0) + 1;
      await new Promise((r) => setTimeout(r, {SLOW_MS}));
    }}
    return resp;
  }};
}})();
"""


def test_a_slow_synopsis_is_asked_for_less_often(page, server_factory, scenario_records):
    srv = server_factory("slow-synopsis")
    page.add_init_script(SLOW_SYNOPSIS_JS)
    open_console(page, srv)
    with srv.client() as c:
        post_until(c, scenario_records, -1.0, 4.0)
        page.wait_for_function("window.demtrack.ui.synopsisFetchMs > 0", timeout=60_000)
        asked = page.evaluate("window.synopsisCalls")
        # 15 s of live data, a second of scenario a second: at 3 s a poll this would be
        # four or five more requests; 20 x 0.7 s = 14 s between them allows one or two.
        t_end = time.monotonic() + 15.0
        t = 4.0
        while time.monotonic() < t_end:
            post_until(c, scenario_records, t, t + 1.0, step_s=1.0)
            t += 1.0
            # Waiting through Playwright: the page's requests pass the test's route
            # (loopback only) while Python is inside a Playwright call.
            page.wait_for_timeout(max(0.0, min(1.0, t_end - time.monotonic())) * 1000)
    assert page.evaluate("window.demtrack.timeline.live")
    assert page.evaluate("window.demtrack.ui.synopsisFetchMs") >= SLOW_MS
    more = page.evaluate("window.synopsisCalls") - asked
    assert 1 <= more <= 2, more
    assert page.record.errors == []
