"""The service: settings, the MQTT connection, the dispatcher, DRC sessions, telemetry scheduling,
metrics, the CLI and the composition root. The only package that knows both MQTT and devices."""
