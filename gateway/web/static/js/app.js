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

const ctx = { session: null, catalog: null, ws: null, state: null, retry: 500, drawing: false };

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
  map.render(msg);
  instruments.render(msg);
  drc.render(msg.drc);
  cloudControl.render(msg.cloud_control);
  frames.links(msg.devices);
}

function connect() {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/api/ws`;
  const ws = new WebSocket(url);
  ctx.ws = ws;
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
    }
  };
  ws.onclose = () => {
    pill.textContent = "disconnected";
    pill.className = "pill off";
    ctx.retry = Math.min(ctx.retry * 2, 8000);
    setTimeout(start, ctx.retry);
  };
}

async function start() {
  try {
    await refreshSession();
    if (!ctx.catalog && !(await loadCatalog())) return;
    connect();
  } catch (err) {
    $("#link-state").textContent = "gateway unreachable";
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
  } catch (err) {
    toast(`sign-in refused: ${err.message}`, true);
  }
});

$("#signout").addEventListener("click", async () => {
  await send("DELETE", "/api/session");
  setCsrf(null);
  await refreshSession();
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
start();
