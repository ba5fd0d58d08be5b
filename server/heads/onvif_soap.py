"""ONVIF PTZ SOAP 1.2 messages, written and read with :mod:`xml.etree` (no zeep).

The four PTZ service operations the server uses (ONVIF PTZ Service Specification,
``http://www.onvif.org/ver20/ptz/wsdl``, types from ``http://www.onvif.org/ver10/schema``):
``AbsoluteMove`` (``Position``: ``tt:PanTilt x y``, ``tt:Zoom x`` in the generic spaces,
pan/tilt -1..1, zoom 0..1), ``ContinuousMove`` (``Velocity`` in the generic velocity
spaces, -1..1), ``Stop`` and ``GetStatus`` (answered by ``PTZStatus``: ``Position``,
``MoveStatus`` ``PanTilt``/``Zoom`` ``IDLE``/``MOVING``/``UNKNOWN``, ``UtcTime``).

Credentials go in a WS-Security ``UsernameToken`` with ``PasswordDigest``:
``Base64(SHA-1(nonce + created + password))`` (OASIS Username Token Profile 1.0), the
scheme ONVIF devices require.
"""

from __future__ import annotations

import base64
import hashlib
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import UTC, datetime

__all__ = [
    "NS",
    "PtzPosition",
    "SoapFault",
    "envelope",
    "parse_envelope",
    "parse_status",
    "password_digest",
    "request_body",
]

#: The namespaces, by the prefixes ONVIF documents use.
NS = {
    "env": "http://www.w3.org/2003/05/soap-envelope",
    "tptz": "http://www.onvif.org/ver20/ptz/wsdl",
    "tt": "http://www.onvif.org/ver10/schema",
    "wsse": "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-wssecurity-secext-1.0.xsd",
    "wsu": "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-wssecurity-utility-1.0.xsd",
}
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)

_SPACES = "http://www.onvif.org/ver10/tptz/"
PANTILT_POSITION_SPACE = _SPACES + "PanTiltSpaces/PositionGenericSpace"
ZOOM_POSITION_SPACE = _SPACES + "ZoomSpaces/PositionGenericSpace"
PANTILT_VELOCITY_SPACE = _SPACES + "PanTiltSpaces/VelocityGenericSpace"
ZOOM_VELOCITY_SPACE = _SPACES + "ZoomSpaces/VelocityGenericSpace"
_PW_DIGEST = (
    "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-username-token-profile-1.0"
    "#PasswordDigest"
)
_B64 = (
    "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-soap-message-security-1.0#Base64Binary"
)


def _q(prefix: str, name: str) -> str:
    return f"{{{NS[prefix]}}}{name}"


class SoapFault(Exception):
    """A SOAP fault: its code, subcode and reason text."""

    def __init__(self, code: str, subcode: str, reason: str) -> None:
        super().__init__(f"{code} {subcode}: {reason}".strip())
        self.code, self.subcode, self.reason = code, subcode, reason


@dataclass(frozen=True)
class PtzPosition:
    """A PTZ position or velocity in ONVIF's generic (normalised) spaces."""

    pan: float
    tilt: float
    zoom: float | None = None


def password_digest(nonce: bytes, created: str, password: str) -> str:
    """``Base64(SHA-1(nonce + created + password))``: WS-Security's PasswordDigest."""
    sha = hashlib.sha1(nonce + created.encode("utf-8") + password.encode("utf-8"))  # noqa: S324
    return base64.b64encode(sha.digest()).decode("ascii")


def _security(user: str, password: str) -> ET.Element:
    nonce = os.urandom(16)
    created = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
    sec = ET.Element(_q("wsse", "Security"), {_q("env", "mustUnderstand"): "true"})
    tok = ET.SubElement(sec, _q("wsse", "UsernameToken"))
    ET.SubElement(tok, _q("wsse", "Username")).text = user
    pw = ET.SubElement(tok, _q("wsse", "Password"), {"Type": _PW_DIGEST})
    pw.text = password_digest(nonce, created, password)
    ET.SubElement(tok, _q("wsse", "Nonce"), {"EncodingType": _B64}).text = base64.b64encode(
        nonce
    ).decode("ascii")
    ET.SubElement(tok, _q("wsu", "Created")).text = created
    return sec


def _vector(parent: ET.Element, tag: str, v: PtzPosition, pt_space: str, z_space: str) -> None:
    el = ET.SubElement(parent, _q("tptz", tag))
    ET.SubElement(el, _q("tt", "PanTilt"), {"x": repr(v.pan), "y": repr(v.tilt), "space": pt_space})
    if v.zoom is not None:
        ET.SubElement(el, _q("tt", "Zoom"), {"x": repr(v.zoom), "space": z_space})


def request_body(operation: str, profile: str, vector: PtzPosition | None = None) -> ET.Element:
    """The body element of one PTZ request.

    ``AbsoluteMove`` takes a position, ``ContinuousMove`` a velocity (and gets a 10 s
    ``Timeout``, so a head that loses the server stops by itself), ``Stop`` stops pan,
    tilt and zoom, ``GetStatus`` takes nothing.
    """
    op = ET.Element(_q("tptz", operation))
    ET.SubElement(op, _q("tptz", "ProfileToken")).text = profile
    if operation == "AbsoluteMove" and vector is not None:
        _vector(op, "Position", vector, PANTILT_POSITION_SPACE, ZOOM_POSITION_SPACE)
    elif operation == "ContinuousMove" and vector is not None:
        _vector(op, "Velocity", vector, PANTILT_VELOCITY_SPACE, ZOOM_VELOCITY_SPACE)
        ET.SubElement(op, _q("tptz", "Timeout")).text = "PT10S"
    elif operation == "Stop":
        ET.SubElement(op, _q("tptz", "PanTilt")).text = "true"
        ET.SubElement(op, _q("tptz", "Zoom")).text = "true"
    return op


def envelope(body: ET.Element, user: str | None = None, password: str | None = None) -> bytes:
    """A SOAP 1.2 envelope around ``body`` (with a UsernameToken when ``user`` is given)."""
    env = ET.Element(_q("env", "Envelope"))
    header = ET.SubElement(env, _q("env", "Header"))
    if user is not None:
        header.append(_security(user, password or ""))
    ET.SubElement(env, _q("env", "Body")).append(body)
    return ET.tostring(env, encoding="utf-8", xml_declaration=True)


def parse_envelope(data: bytes) -> tuple[ET.Element | None, ET.Element]:
    """``(header, first body child)`` of an envelope; :class:`SoapFault` for a fault.

    Raises
    ------
    ValueError
        Not XML, or not a SOAP 1.2 envelope with a body element.
    SoapFault
        The body is a ``env:Fault``.
    """
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise ValueError(f"not XML: {exc}") from None
    if root.tag != _q("env", "Envelope"):
        raise ValueError(f"not a SOAP 1.2 envelope (root {root.tag})")
    body = root.find("env:Body", NS)
    if body is None or len(body) == 0:
        raise ValueError("SOAP envelope without a body element")
    first = body[0]
    if first.tag == _q("env", "Fault"):
        code = first.findtext("env:Code/env:Value", "", NS).strip()
        sub = first.findtext("env:Code/env:Subcode/env:Value", "", NS).strip()
        reason = first.findtext("env:Reason/env:Text", "", NS).strip()
        raise SoapFault(code, sub, reason)
    return root.find("env:Header", NS), first


def _float(el: ET.Element | None, attr: str, what: str) -> float:
    if el is None or el.get(attr) is None:
        raise ValueError(f"GetStatus answer has no {what}")
    try:
        return float(el.get(attr, ""))
    except ValueError:
        raise ValueError(f"GetStatus answer: {what} is not a number: {el.get(attr)!r}") from None


def parse_status(response: ET.Element) -> tuple[PtzPosition, bool, str | None]:
    """``(position, moving, utc_time)`` of a ``GetStatusResponse`` element."""
    if response.tag != _q("tptz", "GetStatusResponse"):
        raise ValueError(f"expected GetStatusResponse, got {response.tag}")
    status = response.find("tptz:PTZStatus", NS)
    if status is None:
        raise ValueError("GetStatus answer has no PTZStatus")
    pt = status.find("tt:Position/tt:PanTilt", NS)
    zoom = status.find("tt:Position/tt:Zoom", NS)
    pos = PtzPosition(
        _float(pt, "x", "PanTilt x"),
        _float(pt, "y", "PanTilt y"),
        _float(zoom, "x", "Zoom x") if zoom is not None else None,
    )
    moves = [
        (status.findtext(f"tt:MoveStatus/tt:{axis}", "", NS) or "").strip().upper()
        for axis in ("PanTilt", "Zoom")
    ]
    utc = status.findtext("tt:UtcTime", None, NS)
    return pos, "MOVING" in moves, utc.strip() if utc else None
