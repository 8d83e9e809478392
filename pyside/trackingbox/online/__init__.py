"""The online mode: live tracking against an OPC UA server, and a replayed bench served as a simulated DCS.

``trackingbox track SPEC --live opc.tcp://HOST:PORT`` (:mod:`.live`) and
``trackingbox replay CASE --serve opc.tcp://HOST:PORT`` (:mod:`.replay`).
"""
from __future__ import annotations
