// Instruments panel: gimbal yaw/pitch/roll as dials, the aircraft's attitude, heading, altitude, speeds and
// battery, the robot's HP, heat, energy and position. Drawn in SVG, redrawn on every push.
import { $, h, s, clear, fmt } from "./dom.js";

const cards = new Map();
const drawn = new Map(); // sn -> the osd the card shows

//: DJI Cloud API osd mode_code (aircraft): the names shown, the number in the tooltip
const MODES = {
  0: "standby", 1: "take-off preparation", 2: "take-off ready", 3: "manual flight", 4: "automatic take-off",
  5: "wayline flight", 6: "panoramic photo", 7: "intelligent tracking", 8: "ADS-B avoidance",
  9: "automatic return home", 10: "automatic landing", 11: "forced landing", 12: "three-propeller landing",
  13: "upgrading", 14: "not connected", 15: "APAS", 16: "virtual stick", 17: "live flight control",
  18: "airborne RTK fixing", 19: "dock address selecting",
};

export function modeName(code) {
  return typeof code === "number" ? MODES[code] || `mode ${code}` : "—";
}

// compass dials (north up) say N/E/S/W; a dial of an angle relative to something (a gimbal's yaw against its
// base) says 0°/90°/180°/−90° and "relative" in its value line
function dial(label, value, { min = -180, max = 180, full = true, relative = false } = {}) {
  const svg = s("svg", { viewBox: "0 0 130 130", class: "dial-svg", "data-label": label });
  const c = 65;
  const r = 52;
  svg.append(s("circle", { cx: c, cy: c, r, class: "dial" }));
  const span = full ? 360 : 180;
  const angleOf = (v) => (full ? v : ((v - min) / (max - min)) * 180 - 90);
  const marks = full ? [0, 45, 90, 135, 180, 225, 270, 315] : [min, (min + max) / 2, max, (min * 3 + max) / 4, (min + max * 3) / 4];
  for (const m of marks) {
    const a = ((angleOf(m) - 90) * Math.PI) / 180;
    svg.append(s("line", { x1: c + Math.cos(a) * (r - 8), y1: c + Math.sin(a) * (r - 8), x2: c + Math.cos(a) * r, y2: c + Math.sin(a) * r, class: "tick" }));
  }
  const names = relative ? [["0", 0], ["90", 90], ["180", 180], ["−90", 270]] : [["N", 0], ["E", 90], ["S", 180], ["W", 270]];
  if (full) for (const [t, a] of names) {
    const rad = ((a - 90) * Math.PI) / 180;
    svg.append(s("text", { x: c + Math.cos(rad) * (r - 16) - 3 * t.length, y: c + Math.sin(rad) * (r - 16) + 4, text: t }));
  }
  if (typeof value === "number") {
    const a = ((angleOf(Math.max(min, Math.min(max, value))) - 90) * Math.PI) / 180;
    svg.append(s("line", { x1: c, y1: c, x2: c + Math.cos(a) * (r - 10), y2: c + Math.sin(a) * (r - 10), class: "needle" }));
  }
  svg.append(s("text", { x: c, y: c + 26, "text-anchor": "middle", class: "value", text: `${label} ${fmt(value)}°${relative ? " rel." : ""}` }));
  if (relative) svg.dataset.relative = "true";
  void span;
  return svg;
}

function horizon(pitch, roll, label = "attitude") {
  const svg = s("svg", { viewBox: "0 0 130 130", "data-label": label });
  const clip = `clip-${Math.random().toString(36).slice(2)}`;
  const defs = s("defs", {}, s("clipPath", { id: clip }, s("circle", { cx: 65, cy: 65, r: 52 })));
  const shift = Math.max(-50, Math.min(50, (pitch || 0) * 1.2));
  const g = s("g", { "clip-path": `url(#${clip})` },
    s("g", { transform: `rotate(${-(roll || 0)} 65 65) translate(0 ${shift})` },
      s("rect", { x: -60, y: -100, width: 250, height: 165, class: "sky" }),
      s("rect", { x: -60, y: 65, width: 250, height: 165, class: "ground" }),
      s("line", { x1: -60, y1: 65, x2: 190, y2: 65, class: "horizon" })));
  svg.append(defs, g, s("circle", { cx: 65, cy: 65, r: 52, class: "dial", fill: "none" }),
    s("path", { d: "M35,65 L55,65 L60,72 L65,65 L70,72 L75,65 L95,65", class: "wing" }),
    s("text", { x: 65, y: 124, "text-anchor": "middle", class: "value",
      text: label === "roll" ? `roll ${fmt(roll)}°` : `P ${fmt(pitch)}° R ${fmt(roll)}°` }));
  return svg;
}

function readout(pairs) {
  return h("div", { class: "readout" }, ...pairs.flatMap(([k, v]) => [h("span", {}, k), h("span", {}, v)]));
}

function bar(fraction, label) {
  const inner = h("div", {});
  inner.style.width = `${Math.max(0, Math.min(1, fraction || 0)) * 100}%`;
  return h("div", {}, h("div", { class: "muted" }, label), h("div", { class: "bar" }, inner));
}

function gimbalCard(d) {
  const o = d.osd;
  const card = h("div", { class: "instrument gimbal", "data-sn": d.sn, "data-yaw": fmt(o.gimbal_yaw, 2), "data-pitch": fmt(o.gimbal_pitch, 2), "data-roll": fmt(o.gimbal_roll, 2) },
    h("h3", {}, `${d.sn} gimbal${d.payload_index ? ` (${d.payload_index})` : ""}`,
      h("small", {}, " · yaw relative to the gimbal's base, pitch and roll to the horizon")),
    h("div", { class: "row" },
      dial("yaw", o.gimbal_yaw, { relative: true }),
      dial("pitch", o.gimbal_pitch, { min: -90, max: 90, full: false }),
      horizon(0, o.gimbal_roll, "roll")));
  return card;
}

function aircraftCard(d) {
  const o = d.osd;
  const battery = o.battery || {};
  return h("div", { class: "instrument aircraft", "data-sn": d.sn, "data-elevation": fmt(o.elevation, 2), "data-heading": fmt(o.attitude_head, 1) },
    h("h3", {}, `${d.sn} aircraft`),
    h("div", { class: "row" },
      horizon(o.attitude_pitch, o.attitude_roll),
      dial("heading", o.attitude_head),
      h("div", {},
        readout([
          ["height (take-off)", `${fmt(o.elevation)} m`],
          ["altitude (WGS84)", `${fmt(o.height)} m`],
          ["horizontal", `${fmt(o.horizontal_speed)} m/s`],
          ["vertical", `${fmt(o.vertical_speed)} m/s`],
          ["position", `${fmt(o.latitude, 6)}, ${fmt(o.longitude, 6)}`],
          ["mode", h("span", { title: `mode_code ${fmt(o.mode_code)}`, "data-mode-code": fmt(o.mode_code) }, modeName(o.mode_code))],
        ]),
        bar((battery.capacity_percent ?? 0) / 100, `battery ${fmt(battery.capacity_percent)} %`))));
}

function robotCard(d) {
  const o = d.osd;
  const pos = o.x_position || {};
  return h("div", { class: "instrument robot", "data-sn": d.sn, "data-hp": fmt(o.x_hp) },
    h("h3", {}, `${d.sn} robot`),
    h("div", { class: "row" },
      dial("heading", o.attitude_head),
      h("div", {},
        bar((o.x_hp ?? 0) / (o.x_max_hp || 1), `HP ${fmt(o.x_hp)} / ${fmt(o.x_max_hp)}`),
        readout([
          ["shooter heat", Array.isArray(o.x_shooter_heat) ? o.x_shooter_heat.join(" / ") : fmt(o.x_shooter_heat)],
          ["buffer energy", fmt(o.x_buffer_energy)],
          ["position", `(${fmt(pos.x)}, ${fmt(pos.y)}) m`],
          ["robot id", fmt(o.x_robot_id)],
          ["stage time left", `${fmt(o.x_stage_remain_time)} s`],
        ]))));
}

export function render(state) {
  const list = $("#instrument-list");
  const seen = new Set();
  for (const d of state.devices) {
    const o = d.osd;
    if (!o) continue;
    const kind = typeof o.gimbal_yaw === "number" ? gimbalCard : typeof o.latitude === "number" ? aircraftCard
      : o.x_hp !== undefined || o.x_position ? robotCard : null;
    if (!kind) continue;
    const key = JSON.stringify(o);
    seen.add(d.sn);
    if (drawn.get(d.sn) === key) continue;
    drawn.set(d.sn, key);
    const card = kind(d);
    const old = cards.get(d.sn);
    if (old) old.replaceWith(card);
    else list.append(card);
    cards.set(d.sn, card);
  }
  for (const [sn, card] of cards) if (!seen.has(sn)) { card.remove(); cards.delete(sn); drawn.delete(sn); }
  if (!cards.size && !list.firstChild) list.append(h("p", { class: "muted" }, "no telemetry yet"));
  else for (const p of list.querySelectorAll("p.muted")) p.remove();
  void clear;
}
