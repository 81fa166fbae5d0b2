"""RoboMaster "DJI serial": the 0xA5 frame (``protocol``), the referee-system tables by season and
the gateway's control messages (``commands``), and the CLI view (``describe``)."""
