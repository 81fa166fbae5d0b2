"""Live video (issue #36): video sources per device, the ``live_*`` services, ffmpeg pipelines.

- :mod:`gateway.video.machine`: one stream's life as a sans-I/O state machine (start, retry, stop).
- :mod:`gateway.video.engine`: the ffmpeg command lines and the parsing of its progress (pure).
- :mod:`gateway.video.service`: the services, ``live_capacity`` / ``live_status``, and the supervised
  ffmpeg processes (the thin transport: asyncio subprocesses, never blocking the loop).
"""
