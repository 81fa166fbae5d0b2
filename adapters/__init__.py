"""Device side of the gateway: one sub-package per DJI device family.

Owns wire protocols, device links and simulators. Must not know MQTT or the
dispatcher: it depends on ``schemas`` (the contract) only, never on ``gateway``.
"""
