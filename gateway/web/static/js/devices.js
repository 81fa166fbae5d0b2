// Devices panel: every device's link, traffic, errors, authority and firmware; the broker connection(s).
import { $, h, clear, fmt } from "./dom.js";

const rows = new Map();
const drawn = new Map(); // sn -> what the row shows (redrawn only when it changes)
let brokersDrawn = "";

//: data older than this is shown as stale, older than OFFLINE_S as offline (whatever the adapter's flag
//: says): the simulated and real devices push several times a second, a quiet link is news
export const STALE_S = 3;
export const OFFLINE_S = 10;

export function freshness(device) {
  if (!device.online) return "offline";
  const age = device.last_heard_s;
  if (age === null || age === undefined) return "stale";
  return age > OFFLINE_S ? "offline" : age > STALE_S ? "stale" : "live";
}

/** The gateway is not heard: nothing the rows say is known to be current. */
export function markUnknown() {
  for (const row of rows.values()) {
    row.dataset.fresh = "unknown";
    const cell = row.children[3];
    if (cell) cell.replaceChildren(h("span", { class: "dot unknown" }), "unknown (gateway not heard)");
  }
  drawn.clear();
}

function cells(device) {
  const link = device.link || {};
  const fresh = freshness(device);
  const label = fresh === "live" ? "online" : fresh === "stale" ? `stale (${fmt(device.last_heard_s)} s)` : "offline";
  const online = h("td", { title: `stale after ${STALE_S} s without data, offline after ${OFFLINE_S} s` },
    h("span", { class: `dot ${fresh === "live" ? "on" : fresh}` }), label);
  const authority = device.authority.holder
    ? [device.authority.flight ? "flight" : null, device.authority.payload ? "payload" : null].filter(Boolean).join(" + ") + " (A)"
    : "—";
  return [
    h("td", { class: "mono" }, device.sn, device.payload_index ? ` · ${device.payload_index}` : ""),
    h("td", {}, device.family),
    h("td", { class: "mono" }, device.link ? `${link.kind} ${link.where}${link.up ? "" : " (down)"}` : "—"),
    online,
    h("td", { class: "mono" }, fmt(link.frames_in)),
    h("td", { class: "mono" }, fmt(link.frames_out)),
    h("td", { class: "mono" }, fmt(link.crc_errors)),
    h("td", { class: "mono" }, fmt(link.framing_errors)),
    h("td", { class: "mono" }, device.last_heard_s === null ? "never" : `${fmt(device.last_heard_s)} s ago`),
    h("td", {}, authority),
    h("td", { class: "mono" }, device.firmware || "—"),
  ];
}

export function render(state) {
  const body = $("#device-table tbody");
  const seen = new Set();
  for (const device of state.devices) {
    seen.add(device.sn);
    let row = rows.get(device.sn);
    if (!row) {
      row = h("tr", { "data-sn": device.sn });
      rows.set(device.sn, row);
      body.append(row);
    }
    const key = JSON.stringify([device.link, device.online, device.last_heard_s, device.authority, device.firmware]);
    if (drawn.get(device.sn) === key) continue;
    drawn.set(device.sn, key);
    row.dataset.online = String(device.online);
    row.dataset.fresh = freshness(device);
    row.replaceChildren(...cells(device));
  }
  for (const [sn, row] of rows) {
    if (!seen.has(sn)) {
      row.remove();
      rows.delete(sn);
      drawn.delete(sn);
    }
  }
  const twin = state.gateway.sn_conflict || null;
  const key = JSON.stringify([state.gateway.brokers, Math.round(state.gateway.uptime_s), state.gateway.requests_in_flight, twin]);
  if (key === brokersDrawn) return;
  brokersDrawn = key;
  const brokers = clear($("#brokers"));
  if (twin && twin.count) {
    // two gateways with one serial number on one broker: never shown as one (gateway/twins.py)
    brokers.append(h("span", { class: "pill off", id: "sn-conflict", "data-active": String(twin.active),
      title: "an osd under this gateway's serial number that it did not send: another gateway uses the same gateway_sn" },
      `ANOTHER GATEWAY publishes as ${state.gateway.sn} on this broker (${twin.active ? "now" : `last ${fmt(twin.last_age_s)} s ago`}, ${twin.count} osd): give each its own gateway_sn`));
  }
  for (const b of state.gateway.brokers) {
    brokers.append(
      h("span", { class: b.connected ? "pill on" : "pill off", "data-broker": b.name },
        `${b.name} broker ${b.url}: ${b.connected ? (b.subscribed ? "connected" : "connected, subscribing") : "disconnected"}`
        + (b.nodes && b.nodes.length > 1 ? ` (nodes: ${b.nodes.join(", ")})` : "")),
    );
  }
  brokers.append(h("span", { class: "muted" }, `gateway ${state.gateway.sn} · v${state.gateway.version} · up ${fmt(state.gateway.uptime_s, 0)} s · ${state.gateway.requests_in_flight} request(s) in flight`));
}
