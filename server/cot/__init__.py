"""Cursor-on-Target out to TAK: the live tracks and the markers as CoT events.

``target`` parses ``DEMTRACK_COT_URL`` (``udp://239.2.3.1:6969``, ``tcp://host:8087``);
``transport`` sends over UDP (unicast or multicast, with a TTL) or TCP (reconnecting, bare
events back to back as TAK Server reads them); ``events`` turns stream messages (track
updates, fixes, markers) into :class:`~demtrack.core.io.cot.CotEvent`; ``sender`` follows
the pipeline's published messages like any other subscriber, through a bounded queue
that drops rather than slows ingest. Imports ``demtrack.core`` and nothing else of the
server.
"""
