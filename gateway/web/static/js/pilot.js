// Live control from the page (issue #35): the keyboard (and a gamepad, where the browser has one) drive
// DRC sticks through the page's WebSocket; the gateway feeds them to the live-control session as a cloud's
// drc/down messages on its main link (seq, stick and heartbeat timeouts, authority: docs/drc.md).
//
// Dead-man: a key's release, the window's blur, a hidden tab or a lost WebSocket zero the sticks at once
// (a zero stick is sent then, not at the next period); the gateway zeroes them too when the page's sticks
// stop for drc.stick_timeout (0.5 s) or its heartbeats for drc.heartbeat_timeout, and when the page's
// WebSocket closes. Sticks: x left +, y forward +, h up +, w yaw clockwise + (the seed's; fly.py's keys).
//
// Gamepad: only a pad with the browser's standard mapping is used (another pad's axes 2 and 3 may be
// triggers resting at -1: full sideways); it is read every period, and a pad that goes (unplugged, or the
// browser's `gamepaddisconnected`) zeroes its sticks at once. A pad found, or taken control with, moves
// nothing until its sticks have been centred once (a stick held over at the start does not fly off).
import { $, fmt, toast } from "./dom.js";
import { send, csrfToken } from "./api.js";

export const PERIOD_MS = 100; // 10 Hz sticks: the control period
const HEARTBEAT_MS = 1000;
const DEADZONE = 0.15;

// key → [axis, direction]: the same keys as `dji-gateway fly`
const KEYS = {
  w: ["y", 1], arrowup: ["y", 1], s: ["y", -1], arrowdown: ["y", -1],
  a: ["x", 1], arrowleft: ["x", 1], d: ["x", -1], arrowright: ["x", -1],
  r: ["h", 1], f: ["h", -1], q: ["w", -1], e: ["w", 1],
};

const pilot = {
  flying: false, // the operator took control from this page
  held: new Map(), // key → [axis, direction]
  timer: null,
  since: 0, // when this page took control (a push gathered before that may still say drc_state 0)
  lastBeat: 0,
  sent: { x: 0, y: 0, h: 0, w: 0 },
  ws: null, // () => the open WebSocket or null
  catalog: null,
  ask: null, // the confirmation dialog (actions.js)
  aircraft: null, // the sn the sticks move (shown in the confirmation)
  pad: null, // the id of the gamepad in use (its loss is told and zeroes its sticks)
  padArmed: false, // its sticks were centred since it was found or control was taken
  padIgnored: new Set(), // ids of pads without the standard mapping (told once)
};

function limits() {
  const speed = Number($("#pilot-speed").value) || 2;
  return { x: speed, y: speed, h: 1, w: 30 };
}

function sticks() {
  const out = { x: 0, y: 0, h: 0, w: 0 };
  const scale = limits();
  for (const [axis, sign] of pilot.held.values()) out[axis] = sign * scale[axis];
  const pad = gamepad();
  if (pad) {
    for (const axis of Object.keys(out)) if (pad[axis] !== 0) out[axis] = pad[axis] * scale[axis];
  }
  return out;
}

/** The first connected pad with the standard mapping (others are told once and never read). */
function findPad() {
  let pads = [];
  try {
    pads = typeof navigator.getGamepads === "function" ? Array.from(navigator.getGamepads() || []) : [];
  } catch {
    pads = []; // a browser that refuses the Gamepad API here (permissions policy): no pad
  }
  for (const p of pads) {
    if (!p || !p.connected) continue;
    if (p.mapping === "standard" && p.axes && p.axes.length >= 4) return p;
    if (!pilot.padIgnored.has(p.id)) {
      pilot.padIgnored.add(p.id);
      toast(`gamepad ${p.id} ignored: the browser knows no standard mapping for it`, true);
    }
  }
  return null;
}

/** The pad's axes (deadzone applied), or null: no pad, or its sticks not centred yet since it was found. */
function gamepad() {
  const pad = findPad();
  if (!pad) {
    if (pilot.pad !== null) {
      toast(`gamepad lost (${pilot.pad}): its sticks zeroed`, true);
      pilot.pad = null;
    }
    return null;
  }
  if (pilot.pad !== pad.id) {
    pilot.pad = pad.id;
    pilot.padArmed = false;
    toast(`gamepad found: ${pad.id}${pilot.flying ? "" : " (it flies once you take control)"}`);
  }
  // the standard mapping: left stick yaw (x) and climb (y), right stick lateral (x) and forward (y)
  const dz = (v) => (Math.abs(v) < DEADZONE ? 0 : v);
  const axes = { w: dz(pad.axes[0]), h: -dz(pad.axes[1]), x: -dz(pad.axes[2]), y: -dz(pad.axes[3]) };
  if (!pilot.padArmed) {
    if (Object.values(axes).some((v) => v !== 0)) return null;
    pilot.padArmed = true;
  }
  return axes;
}

/** A pad came or went (the browser's events): told now; while flying its loss zeroes the sticks at once. */
function onPadChange(event) {
  if (pilot.flying) tick(event.type === "gamepaddisconnected" ? "gamepad lost" : undefined);
  else gamepad();
}

function wire(method, data) {
  const ws = pilot.ws && pilot.ws();
  if (!ws || ws.readyState !== 1) return false;
  ws.send(JSON.stringify({ type: "drc", csrf: csrfToken(), method, data }));
  return true;
}

function show(values, why) {
  const box = $("#pilot-sticks");
  box.textContent = `sticks: forward ${fmt(values.y, 1)} m/s · left ${fmt(values.x, 1)} m/s · up ${fmt(values.h, 1)} m/s · yaw ${fmt(values.w, 0)} °/s${why ? ` (${why})` : ""}`;
  for (const axis of ["x", "y", "h", "w"]) box.dataset[axis] = String(values[axis]);
}

function tick(why) {
  if (!pilot.flying) return;
  const now = Date.now();
  if (now - pilot.lastBeat >= HEARTBEAT_MS) {
    wire("heart_beat", { timestamp: now });
    pilot.lastBeat = now;
  }
  const values = sticks();
  if (!wire("drone_control", values)) {
    stop("the connection to the gateway is lost: sticks zeroed (the gateway zeroes them too)");
    return;
  }
  pilot.sent = values;
  show(values, why || (pilot.pad !== null && !pilot.padArmed ? "centre the gamepad's sticks to fly with it" : ""));
}

/** Zero every axis and send that at once (the dead-man). */
function zero(why) {
  pilot.held.clear();
  if (pilot.flying) tick(why);
}

function setState(state, text) {
  const pill = $("#pilot-state");
  pill.dataset.state = state;
  pill.textContent = text;
  pill.className = `pill ${state === "flying" ? "on" : state === "off" ? "" : "warn"}`;
  $("#pilot-take").hidden = state === "flying";
  $("#pilot-release").hidden = state !== "flying";
  document.body.classList.toggle("piloting", state === "flying");
}

function stop(why) {
  if (pilot.timer) clearInterval(pilot.timer);
  pilot.timer = null;
  pilot.held.clear();
  const was = pilot.flying;
  pilot.flying = false;
  show({ x: 0, y: 0, h: 0, w: 0 }, why);
  setState("off", why || "not flying");
  if (was && why) toast(why, true);
}

async function take() {
  if (!pilot.catalog) return;
  const gw = pilot.catalog.gateway;
  const lim = limits();
  const target = pilot.aircraft || "the aircraft";
  const text =
    `Fly ${target} from this page: while a key is held (or a gamepad's stick pushed) it moves at up to ${lim.y} m/s forward/back and ` +
    `left/right, ${lim.h} m/s up/down and ${lim.w} °/s yaw; it stops (hovers) when the key is released, the ` +
    `window or tab loses focus, or the connection drops. The gateway ${gw.sn} grabs flight authority and ` +
    `enters live control on its own broker (${gw.prefill.mqtt_broker.address}).`;
  if (!(await pilot.ask(text))) return;
  setState("entering", "grabbing flight authority …");
  try {
    const grab = await send("POST", "/api/action", { method: "flight_authority_grab", data: {}, confirm: false });
    if (grab.result !== 0) throw new Error(`flight_authority_grab: result ${grab.result} ${JSON.stringify(grab.output || {})}`);
    setState("entering", "entering live control …");
    const data = structuredClone(gw.prefill);
    data.mqtt_broker.password = "-"; // the gateway's own connection: no credentials are used
    data.mqtt_broker.expire_time = Math.floor(Date.now() / 1000) + 3600;
    const enter = await send("POST", "/api/action", { method: "drc_mode_enter", data, confirm: true });
    if (enter.result !== 0) throw new Error(`drc_mode_enter: result ${enter.result} ${JSON.stringify(enter.output || {})}`);
  } catch (err) {
    setState("off", `not flying: ${err.message}`);
    toast(`live control refused: ${err.message}`, true);
    return;
  }
  pilot.flying = true;
  pilot.since = Date.now();
  pilot.lastBeat = 0;
  pilot.held.clear();
  pilot.padArmed = false; // a gamepad flies once its sticks were centred
  setState("flying", "flying from this page");
  tick();
  pilot.timer = setInterval(tick, PERIOD_MS);
}

async function release() {
  stop("stopped flying: sticks zeroed");
  wire("drone_control", { x: 0, y: 0, h: 0, w: 0 });
  try {
    await send("POST", "/api/action", { method: "drc_mode_exit", data: {}, confirm: false });
  } catch (err) {
    toast(`drc_mode_exit refused: ${err.message}`, true);
  }
}

function typing(event) {
  const t = event.target;
  return t && (t.tagName === "INPUT" || t.tagName === "SELECT" || t.tagName === "TEXTAREA" || t.isContentEditable);
}

function onKeyDown(event) {
  if (!pilot.flying || typing(event) || event.ctrlKey || event.metaKey || event.altKey) return;
  const key = event.key.toLowerCase();
  if (key === "x") {
    event.preventDefault();
    $("#estop").click(); // the one emergency stop: every device; the session holds, flying here ends
    return;
  }
  if (key === "escape") {
    event.preventDefault();
    release();
    return;
  }
  if (key === " ") {
    event.preventDefault();
    zero("space: all sticks released");
    return;
  }
  const binding = KEYS[key];
  if (!binding) return;
  event.preventDefault();
  if (event.repeat && pilot.held.has(key)) return;
  for (const [k, [axis]] of pilot.held) if (axis === binding[0]) pilot.held.delete(k); // the opposite key takes over
  pilot.held.set(key, binding);
  tick(); // at once: stick-to-wire is not a period
}

function onKeyUp(event) {
  const key = event.key.toLowerCase();
  if (!pilot.held.has(key)) return;
  pilot.held.delete(key);
  tick("key released");
}

export function configure(catalog, ws, ask) {
  pilot.catalog = catalog;
  pilot.ws = ws;
  pilot.ask = ask;
  const aircraft = catalog.devices.find((d) => d.methods.some((m) => m.method === "takeoff_to_point"));
  pilot.aircraft = aircraft ? aircraft.sn : null;
  $("#pilot-target").textContent = pilot.aircraft ? `moves ${pilot.aircraft}` : "no aircraft here: sticks move the robot or gimbals";
}

/** The page's WebSocket closed: nothing can be sent; the gateway zeroes the sticks on its side. */
export function connectionLost() {
  if (pilot.flying) stop("the connection to the gateway is lost: sticks zeroed (the gateway zeroes them too)");
}

/** Shown in the DRC panel: whether the session is one this page can fly. */
export function render(drc) {
  if (!drc || !pilot.flying) return;
  if (drc.state === 0 && Date.now() - pilot.since > 2000) {
    stop("live control ended by the gateway (drc_state 0): sticks zeroed");
  }
}

export function refused(msg) {
  toast(`live control refused: ${msg.reason}`, true);
  if (pilot.flying && /sign in|CSRF|read-only|token/.test(msg.reason)) stop(`not flying: ${msg.reason}`);
}

export function init() {
  // the emergency stop (button, X, its access key) ends flying from this page: the session holds until
  // the operator takes control again (a new drc_mode_enter releases the hold; docs/drc.md)
  $("#estop").addEventListener("click", () => {
    if (pilot.flying) stop("EMERGENCY STOP: sticks stopped; take control again to fly");
  });
  $("#pilot-take").addEventListener("click", take);
  $("#pilot-release").addEventListener("click", release);
  window.addEventListener("keydown", onKeyDown);
  window.addEventListener("keyup", onKeyUp);
  window.addEventListener("blur", () => zero("the window lost focus"));
  document.addEventListener("visibilitychange", () => {
    if (document.visibilityState !== "visible") zero("the tab is hidden");
  });
  window.addEventListener("pagehide", () => zero("the page is closing"));
  window.addEventListener("gamepadconnected", onPadChange);
  window.addEventListener("gamepaddisconnected", onPadChange);
  setState("off", "not flying");
  show({ x: 0, y: 0, h: 0, w: 0 });
}
