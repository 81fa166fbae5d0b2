#!/bin/sh
# The compose stack's mosquitto: write the password file from the environment, then become mosquitto.
# Passwords never sit in the repository or the image; set them in .env (see docker-compose.yml).
#   DJIGW_GATEWAY_USER / DJIGW_GATEWAY_PASSWORD   the gateway's login (user name = its serial number)
#   DJIGW_CLOUD_USER / DJIGW_CLOUD_PASSWORD       the cloud's login (and dji-gateway send/monitor)
# PASSWD_FILE and MOSQUITTO_CONF move the files (tests/test_deploy.py runs this script outside a container).
set -eu
PASSWD_FILE="${PASSWD_FILE:-/mosquitto/data/passwd}"
MOSQUITTO_CONF="${MOSQUITTO_CONF:-/mosquitto/config/mosquitto.conf}"
: "${DJIGW_GATEWAY_PASSWORD:?set DJIGW_GATEWAY_PASSWORD}"
: "${DJIGW_CLOUD_PASSWORD:?set DJIGW_CLOUD_PASSWORD}"

umask 077
mkdir -p "$(dirname "$PASSWD_FILE")"
rm -f "$PASSWD_FILE"
mosquitto_passwd -c -b "$PASSWD_FILE" "${DJIGW_GATEWAY_USER:-DJIGW-0001}" "$DJIGW_GATEWAY_PASSWORD"
mosquitto_passwd -b "$PASSWD_FILE" "${DJIGW_CLOUD_USER:-cloud}" "$DJIGW_CLOUD_PASSWORD"
if [ "$(id -u)" = "0" ] && id mosquitto >/dev/null 2>&1; then
    # the image's mosquitto drops to this user and must still read its files
    chown mosquitto:mosquitto "$PASSWD_FILE" "$(dirname "$PASSWD_FILE")"
fi
exec mosquitto -c "$MOSQUITTO_CONF"
