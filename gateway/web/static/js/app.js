// The console's entry point: sign-in, the catalogue, the live connection, and each panel fed from it.
import { get, send, setCsrf, HttpError } from "./api.js";
import { $, toast } from "./dom.js";
import * as devices from "./devices.js";
import * as map from "./map.js";
import * as instruments from "./instruments.js";
import * as drc from "./drc.js";
import * as frames from "./frames.js";
import * as journal from "./journal.js";
import * as actions from "./actions.js";
import * as cloudControl from "./cloudcontrol.js";
import * as pilot from "./pilot.js";

const ctx = { session: null, catalog: null, ws: null, state: null, retry: 500, drawing: false, heard: 0 };
//: the gateway pushes a state at least once a second (console.push_hz ≥ 1): none for this long and the
//: page is marked as showing old data (greyed) until the next one
const SILENT_MS = 2000;

/** The whole page greys, saying since when, while the gateway is not heard (stale is never shown as live). */
function markGone(why) {
  if (document.body.classList.contains("gone")) return;
  document.body.classList.add("gone");
  const since = ctx.heard ? new Date(ctx.heard).toLocaleTimeString([], { hour12: false }) : "the start";
  const banner = $("#gone");
  banner.textContent = `${why}: everything below is as of ${since}, not live`;
  banner.hidden = false;
  devices.markUnknown();
}

function markLive() {
  if (!document.body.classList.contains("gone")) return;
  document.body.classList.remove("gone");
  $("#gone").hidden = true;
}

setInterval(() => {
  if (ctx.ws && ctx.ws.readyState === 1 && ctx.heard && Date.now() - ctx.heard > SILENT_MS) {
    markGone("no news from the gateway for more than 2 s");
  }
}, 250);

function showSession() {
  const s = ctx.session || {};
  $("#gw-sn").textContent = s.gateway_sn || "";
  $("#signin").hidden = !!s.signed_in;
  $("#signedin").hidden = !s.signed_in;
  const mode = $("#mode");
  mode.textContent = s.read_only ? "read-only" : !s.token_configured ? "view only: no console.token" : "";
  mode.className = "pill warn";
  actions.setAllowed(!!s.signed_in && !s.read_only && !!s.token_configured, s);
}

async function refreshSession() {
  ctx.session = await get("/api/session");
  setCsrf(ctx.session.csrf);
  showSession();
}

async function loadCatalog() {
  try {
    ctx.catalog = await get("/api/catalog");
  } catch (err) {
    if (err instanceof HttpError && err.status === 401) {
      toast("sign in with the console token to see the gateway", true);
      return false;
    }
    throw err;
  }
  actions.setCatalog(ctx.catalog);
  map.configure(ctx.catalog.config);
  frames.configure(ctx.catalog.config, (message) => ctx.ws && ctx.ws.readyState === 1 && ctx.ws.send(JSON.stringify(message)));
  pilot.configure(ctx.catalog, () => ctx.ws, actions.ask);
  try {
    map.setTracks(await get("/api/tracks"));
  } catch {
    /* the pushes draw the tracks from now on */
  }
  return true;
}

function draw() {
  ctx.drawing = false;
  const msg = ctx.state;
  devices.render(msg);
  actions.setState(msg);
  map.render(msg);
  instruments.render(msg);
  drc.render(msg.drc);
  pilot.render(msg.drc);
  cloudControl.render(msg.cloud_control);
  frames.links(msg.devices);
}

function connect() {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/api/ws`;
  const ws = new WebSocket(url);
  ctx.ws = ws;
  // a socket that has not opened in 8 s is closed: its onclose retries (never "connecting" for ever)
  setTimeout(() => { if (ws.readyState === 0) ws.close(); }, 8000);
  const pill = $("#link-state");
  ws.onopen = () => {
    ctx.retry = 500;
    pill.textContent = "live";
    pill.className = "pill on";
    frames.resubscribe();
  };
  ws.onmessage = (event) => {
    const msg = JSON.parse(event.data);
    if (msg.type === "state") {
      ctx.heard = Date.now();
      markLive();
      // draw at most once per frame, the newest state (pushes may come faster than a busy page draws)
      const first = !ctx.state;
      ctx.state = msg;
      if (first || !ctx.drawing) {
        ctx.drawing = true;
        requestAnimationFrame(draw);
      }
      pill.textContent = "live";
      pill.className = "pill on";
    } else if (msg.type === "stalled") {
      pill.textContent = "gateway loop stalled";
      pill.className = "pill warn";
    } else if (msg.type === "journal") {
      journal.add(msg.entries);
    } else if (msg.type === "frames") {
      frames.add(msg);
    } else if (msg.type === "drc_refused") {
      pilot.refused(msg);
    }
  };
  ws.onclose = () => {
    pilot.connectionLost();
    markGone("the connection to the gateway is lost");
    pill.textContent = "disconnected";
    pill.className = "pill off";
    ctx.retry = Math.min(ctx.retry * 2, 8000);
    setTimeout(start, ctx.retry);
  };
}

/** A new WebSocket for a new sign-in state: the gateway reads who a page is from its WebSocket's request
 * (the session cookie), so live control needs one opened after signing in. */
function renew() {
  const old = ctx.ws;
  if (old) {
    old.onclose = null;
    old.close();
  }
  pilot.connectionLost();
  connect();
}

async function start() {
  try {
    await refreshSession();
    if (!ctx.catalog && !(await loadCatalog())) return;
    connect();
  } catch (err) {
    $("#link-state").textContent = "gateway unreachable";
    if (ctx.heard) markGone("the gateway is unreachable");
    ctx.retry = Math.min(ctx.retry * 2, 8000);
    setTimeout(start, ctx.retry);
  }
}

$("#signin").addEventListener("submit", async (event) => {
  event.preventDefault();
  const input = $("#token");
  try {
    const out = await send("POST", "/api/session", { token: input.value });
    input.value = "";
    setCsrf(out.csrf);
    await refreshSession();
    toast("signed in");
    if (!ctx.catalog && (await loadCatalog()) && !ctx.ws) connect();
    else renew();
  } catch (err) {
    toast(`sign-in refused: ${err.message}`, true);
  }
});

$("#signout").addEventListener("click", async () => {
  await send("DELETE", "/api/session");
  setCsrf(null);
  await refreshSession();
  renew();
});

$("#estop").addEventListener("click", async () => {
  // no confirmation: a stop must never wait for a second click
  try {
    const out = await send("POST", "/api/estop", {});
    const failed = Object.keys(out.failed || {});
    toast(`EMERGENCY STOP sent to ${out.stopped.join(", ") || "no device"}${failed.length ? `; failed: ${failed.join(", ")}` : ""}`, failed.length > 0);
    document.body.dataset.estop = String(Date.now());
  } catch (err) {
    toast(`emergency stop refused: ${err.message}${err.status === 401 ? " (sign in first)" : ""}`, true);
  }
});

actions.init({ refreshSession });
cloudControl.init();
pilot.init();
start();
