"""The gateway's web console: the page at ``/`` of the metrics endpoint and the HTTP server behind it.

``server`` (aiohttp: routes, WebSocket push, its own thread), ``state`` (the one module that reads the
gateway's devices for the page), ``frames`` (the frame inspector's taps and decoding), ``journal`` (events,
requests and replies), ``actions`` (forms from the contract and running them), ``security`` (token,
sign-in, same-origin checks) and ``static/`` (the page: plain ES modules, SVG and canvas, no build step).
See docs/console.md.
"""
