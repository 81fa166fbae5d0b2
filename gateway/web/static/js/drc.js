// DRC panel: the live-control session, the heartbeat delay chart, the last sticks and the failsafe that fired.
import { $, h, fmt, time } from "./dom.js";

const STATES = { 0: "0 idle", 1: "1 connecting", 2: "2 in live control" };

function facts(d) {
  const sp = d.setpoint || {};
  const beats = d.heartbeats || [];
  return [
    ["drc_state", STATES[d.state] || String(d.state)],
    ["session", d.session_state ?? "—"],
    ["broker", d.broker ?? "—"],
    ["holding", d.hold || "—"],
    ["heartbeats", `${beats.length} shown · last ${d.heartbeat_age_s == null ? "—" : `${fmt(d.heartbeat_age_s, 2)} s ago`}`],
    ["last sticks", `fwd ${fmt(sp.forward, 2)} right ${fmt(sp.right, 2)} up ${fmt(sp.up, 2)} yaw ${fmt(sp.yaw_rate, 1)}°/s`],
    ["stick age / seq", `${d.stick_age_s == null ? "—" : `${fmt(d.stick_age_s, 2)} s`} · seq ${fmt(d.last_seq)}`],
    ["streaming", d.streaming ? "yes" : "no"],
    ["failsafe now", d.hold ? `${d.hold}${d.failsafe_reason ? ` (${d.failsafe_reason} at ${time(d.failsafe_at)})` : ""}` : "none holds"],
    ["failsafe history", history.length ? history.slice(-5).reverse().map((f) => `${f.reason} at ${time(f.at)}`).join(" · ") : "none since the page opened"],
    ["command delay", `${fmt(d.command_delay_ms)} ms`],
  ];
}

function chart(beats) {
  const canvas = $("#hb-chart");
  const g = canvas.getContext("2d");
  const w = canvas.width;
  const hgt = canvas.height;
  g.clearRect(0, 0, w, hgt);
  g.strokeStyle = "#2a3440";
  g.fillStyle = "#8393a3";
  g.font = "10px monospace";
  const values = beats.map((b) => b[1]);
  const top = Math.max(10, ...values.map((v) => Math.abs(v))) * 1.2;
  for (let i = 0; i <= 4; i++) {
    const y = (hgt - 14) * (i / 4) + 4;
    g.beginPath();
    g.moveTo(30, y);
    g.lineTo(w, y);
    g.stroke();
    g.fillText(String(Math.round(top * (1 - i / 4))), 2, y + 3);
  }
  if (!beats.length) {
    g.fillText("no heartbeats", 40, hgt / 2);
    return;
  }
  g.strokeStyle = "#3fb6ff";
  g.lineWidth = 2;
  g.beginPath();
  beats.forEach(([, delay], i) => {
    const x = 30 + ((w - 34) * i) / Math.max(1, beats.length - 1);
    const y = 4 + (hgt - 14) * (1 - Math.max(0, delay) / top);
    if (i === 0) g.moveTo(x, y);
    else g.lineTo(x, y);
  });
  g.stroke();
  g.fillStyle = "#3fb6ff";
  beats.forEach(([, delay], i) => {
    const x = 30 + ((w - 34) * i) / Math.max(1, beats.length - 1);
    const y = 4 + (hgt - 14) * (1 - Math.max(0, delay) / top);
    g.fillRect(x - 2, y - 2, 4, 4);
  });
  canvas.dataset.points = String(beats.length);
}

let drawn = "";
//: the failsafes seen while the page is open (the one that holds now is shown apart)
const history = [];

export function render(d) {
  if (!d) return;
  const last = history[history.length - 1];
  if (d.failsafe_reason && d.failsafe_at && !(last && last.reason === d.failsafe_reason && last.at === d.failsafe_at)) {
    history.push({ reason: d.failsafe_reason, at: d.failsafe_at });
    if (history.length > 50) history.shift();
  }
  const key = JSON.stringify(d);
  if (key === drawn) return;
  drawn = key;
  const dl = $("#drc-facts");
  dl.replaceChildren(...facts(d).flatMap(([k, v]) => [h("dt", {}, k), h("dd", {}, v)]));
  dl.dataset.state = String(d.state);
  dl.dataset.heartbeats = String((d.heartbeats || []).length);
  dl.dataset.failsafe = d.failsafe_reason || "";
  dl.dataset.hold = d.hold || "";
  dl.dataset.history = String(history.length);
  chart(d.heartbeats || []);
}
