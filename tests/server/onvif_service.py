"""A small ONVIF PTZ device on loopback, for the adapter's and the controller's tests.

A real HTTP server on 127.0.0.1 (a port the OS picks) that reads the four PTZ requests
the server sends -- ``AbsoluteMove``, ``ContinuousMove``, ``Stop``, ``GetStatus`` -- as
SOAP 1.2 envelopes, moves a :class:`~demtrack.server.heads.simulated.SimulatedHead`, and
answers in the PTZ service's own shapes (``tptz:GetStatusResponse`` / ``tptz:PTZStatus``
/ ``tt:Position`` ``tt:PanTilt x y`` ``tt:Zoom x`` / ``tt:MoveStatus`` / ``tt:UtcTime``).
Everything it parses and writes is built here independently of the client's code, with
its own namespace strings, so a client that writes the wrong element or namespace fails.

With ``user``/``password`` it checks the WS-Security UsernameToken digest and answers a
``ter:NotAuthorized`` fault otherwise. ``fault_next`` makes the next request fail with a
SOAP fault, ``hang_s`` makes every answer wait (for timeout tests).
"""

from __future__ import annotations

import base64
import hashlib
import math
import threading
import time
import xml.etree.ElementTree as ET
from datetime import UTC, datetime
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from demtrack.core.camera.head_motion import SlewLimits
from demtrack.server.heads.simulated import SimulatedHead

ENV = "http://www.w3.org/2003/05/soap-envelope"
TPTZ = "http://www.onvif.org/ver20/ptz/wsdl"
TT = "http://www.onvif.org/ver10/schema"
WSSE = "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-wssecurity-secext-1.0.xsd"
WSU = "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-wssecurity-utility-1.0.xsd"
TER = "http://www.onvif.org/ver10/error"


class OnvifPtzService:
    """The device. Pan x in -1..1 spans ``pan_range_deg``, tilt y ``tilt_range_deg``;
    zoom 0..1 is linear in ``1/tan(hfov/2)`` between ``hfov_deg`` (wide, tele)."""

    def __init__(
        self,
        limits: SlewLimits | None = None,
        *,
        profile: str = "Profile_1",
        pan_range_deg: tuple[float, float] = (-180.0, 180.0),
        tilt_range_deg: tuple[float, float] = (-90.0, 30.0),
        hfov_deg: tuple[float, float] = (60.0, 3.0),
        user: str | None = None,
        password: str | None = None,
        pan_deg: float = 0.0,
        tilt_deg: float = 0.0,
        clock=time.time,
    ) -> None:
        self.limits = limits or SlewLimits()
        self.head = SimulatedHead(self.limits, pan_deg, tilt_deg, hfov_deg[0], clock=clock)
        self.profile, self.user, self.password = profile, user, password
        self.pan_range_deg, self.tilt_range_deg, self.hfov_deg = (
            pan_range_deg,
            tilt_range_deg,
            hfov_deg,
        )
        self.clock = clock
        self.requests: list[str] = []  # operation names, in arrival order
        self.fault_next = False
        self.hang_s = 0.0
        self._server = _QuietServer(("127.0.0.1", 0), self._handler())
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)

    @property
    def url(self) -> str:
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}/onvif/ptz_service"

    def __enter__(self) -> OnvifPtzService:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._server.shutdown()
        self._server.server_close()

    # normalised <-> degrees (the device's own copy of the mapping) -------------------
    def _deg(self, lo_hi: tuple[float, float], v: float) -> float:
        return lo_hi[0] + (v + 1.0) / 2.0 * (lo_hi[1] - lo_hi[0])

    def _norm(self, lo_hi: tuple[float, float], deg: float) -> float:
        return -1.0 + 2.0 * (deg - lo_hi[0]) / (lo_hi[1] - lo_hi[0])

    def _zoom_to_hfov(self, z: float) -> float:
        kw, kt = (1.0 / math.tan(math.radians(h) / 2.0) for h in self.hfov_deg)
        return math.degrees(2.0 * math.atan(1.0 / (kw + z * (kt - kw))))

    def _hfov_to_zoom(self, h: float) -> float:
        kw, kt = (1.0 / math.tan(math.radians(x) / 2.0) for x in self.hfov_deg)
        return (1.0 / math.tan(math.radians(h) / 2.0) - kw) / (kt - kw)

    # requests ---------------------------------------------------------------------
    def _check_auth(self, header: ET.Element | None) -> bool:
        if self.user is None:
            return True
        tok = None if header is None else header.find(f"{{{WSSE}}}Security/{{{WSSE}}}UsernameToken")
        if tok is None:
            return False
        nonce = base64.b64decode(tok.findtext(f"{{{WSSE}}}Nonce", ""))
        created = tok.findtext(f"{{{WSU}}}Created", "")
        want = base64.b64encode(
            hashlib.sha1(nonce + created.encode() + (self.password or "").encode()).digest()
        ).decode()
        return (
            tok.findtext(f"{{{WSSE}}}Username") == self.user
            and tok.findtext(f"{{{WSSE}}}Password") == want
        )

    def handle(self, data: bytes) -> tuple[int, str]:
        root = ET.fromstring(data)
        assert root.tag == f"{{{ENV}}}Envelope", root.tag
        op = root.find(f"{{{ENV}}}Body")[0]
        name = op.tag.split("}")[1]
        assert op.tag == f"{{{TPTZ}}}{name}", op.tag
        self.requests.append(name)
        if self.hang_s:
            time.sleep(self.hang_s)
        if not self._check_auth(root.find(f"{{{ENV}}}Header")):
            return _fault("env:Sender", "ter:NotAuthorized", "Sender not authorized")
        if self.fault_next:
            self.fault_next = False
            return _fault("env:Receiver", "ter:Action", "The requested operation failed")
        if op.findtext(f"{{{TPTZ}}}ProfileToken") != self.profile:
            return _fault("env:Sender", "ter:InvalidArgVal", "No such profile")
        if name == "AbsoluteMove":
            pt = op.find(f"{{{TPTZ}}}Position/{{{TT}}}PanTilt")
            zoom = op.find(f"{{{TPTZ}}}Position/{{{TT}}}Zoom")
            pan = self._deg(self.pan_range_deg, float(pt.get("x")))
            tilt = self._deg(self.tilt_range_deg, float(pt.get("y")))
            hfov = None if zoom is None else self._zoom_to_hfov(float(zoom.get("x")))
            self.head.absolute_move(pan, tilt, hfov)
        elif name == "ContinuousMove":
            pt = op.find(f"{{{TPTZ}}}Velocity/{{{TT}}}PanTilt")
            zoom = op.find(f"{{{TPTZ}}}Velocity/{{{TT}}}Zoom")
            lim = self.limits
            self.head.continuous_move(
                float(pt.get("x")) * lim.pan_rate_deg_s,
                float(pt.get("y")) * lim.tilt_rate_deg_s,
                0.0 if zoom is None else -float(zoom.get("x")) * lim.zoom_rate_deg_s,
            )
        elif name == "Stop":
            self.head.stop()
        elif name == "GetStatus":
            return 200, self._status_xml()
        else:
            return _fault("env:Receiver", "ter:ActionNotSupported", f"{name} not supported")
        return 200, _envelope(f'<tptz:{name}Response xmlns:tptz="{TPTZ}"/>')

    def _status_xml(self) -> str:
        s = self.head.status()
        x = self._norm(self.pan_range_deg, s.pan_deg)
        y = self._norm(self.tilt_range_deg, s.tilt_deg)
        z = self._hfov_to_zoom(s.hfov_deg)
        move = "MOVING" if s.moving else "IDLE"
        utc = datetime.fromtimestamp(s.t_s, UTC).strftime("%Y-%m-%dT%H:%M:%S.%f") + "Z"
        return _envelope(
            f'<tptz:GetStatusResponse xmlns:tptz="{TPTZ}" xmlns:tt="{TT}"><tptz:PTZStatus>'
            "<tt:Position>"
            f'<tt:PanTilt x="{x!r}" y="{y!r}" space="http://www.onvif.org/ver10/tptz/'
            'PanTiltSpaces/PositionGenericSpace"/>'
            f'<tt:Zoom x="{z!r}" space="http://www.onvif.org/ver10/tptz/ZoomSpaces/'
            'PositionGenericSpace"/>'
            "</tt:Position>"
            f"<tt:MoveStatus><tt:PanTilt>{move}</tt:PanTilt><tt:Zoom>IDLE</tt:Zoom></tt:MoveStatus>"
            f"<tt:UtcTime>{utc}</tt:UtcTime>"
            "</tptz:PTZStatus></tptz:GetStatusResponse>"
        )

    def _handler(self):
        service = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - http.server's name
                data = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                code, text = service.handle(data)
                body = text.encode("utf-8")
                self.send_response(code)
                self.send_header("Content-Type", "application/soap+xml; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args: object) -> None:
                pass

        return Handler


class _QuietServer(ThreadingHTTPServer):
    """A client that gave up (the timeout tests) is no traceback on stderr."""

    def handle_error(self, request, client_address) -> None:
        pass


def _envelope(body: str) -> str:
    return (
        f'<?xml version="1.0" encoding="UTF-8"?><env:Envelope xmlns:env="{ENV}">'
        f"<env:Header/><env:Body>{body}</env:Body></env:Envelope>"
    )


def _fault(code: str, subcode: str, reason: str) -> tuple[int, str]:
    return 400, _envelope(
        f'<env:Fault xmlns:ter="{TER}"><env:Code><env:Value>{code}</env:Value>'
        f"<env:Subcode><env:Value>{subcode}</env:Value></env:Subcode></env:Code>"
        f'<env:Reason><env:Text xml:lang="en">{reason}</env:Text></env:Reason></env:Fault>'
    )
