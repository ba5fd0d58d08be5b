"""Pan-tilt-zoom heads under the server's control.

:mod:`.adapter` is the :class:`~.adapter.HeadAdapter` protocol between the server and a
head (status, absolute and continuous moves, stop) and its one error;
:mod:`.simulated` a head that moves by :mod:`demtrack.core.camera.head_motion` on a clock;
:mod:`.onvif` an ONVIF PTZ head over SOAP 1.2 (envelopes in :mod:`.onvif_soap`);
:mod:`.config` builds an adapter per active sensor from ``site.json``;
:mod:`.aim` turns a ground point or a track into a pan and tilt;
:mod:`.controller` runs the heads (idle, slew, look, follow, hand-off) at about 10 Hz
and :mod:`.journal` keeps every slew and assignment so a restart restores them.

May import ``demtrack.core`` and :mod:`demtrack.server.settings`; the app builds the
controller in its lifespan, the routers reach it through the console state.
"""
