"""Wayline (route) tasks of a dock-like gateway: the sans-I/O task state machine (task.py), the KMZ
download (fetch.py) and the service that ties them to the cloud and the aircraft (service.py)."""
