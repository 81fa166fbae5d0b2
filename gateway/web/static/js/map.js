// Map panel: the aircraft on a local metric grid (offline; map tiles under it when the config names a
// tile URL), its trail, home point and the fly-to / take-off target, or the wayline task's route (fetched
// once per task/version from /api/wayline/<flight_id>, decimated by the gateway for a long route) with the
// waypoints reached, the current target and the break point; the robot on its field.
import { $, s, clear, fmt } from "./dom.js";
import { get } from "./api.js";

const R = 6371000;
const W = 600;
const H = 420;
const FIELD = { length: 28, width: 15 }; // RoboMaster field (m)
let tileUrl = null;
let origin = null; // [lat, lon] of the grid's 0,0: the first home point (or position) seen
const tracks = new Map(); // sn -> [[a, b], ...] (lat/lon for aircraft, field metres for robots)
const TRACK_POINTS = 600;
const LABELS = 40; // waypoint numbers drawn (every k-th on a longer route)
let route = null; // the drawn wayline route: {key, waypoints: [[index, lat, lon, height], ...], total}
let routeAsked = null; // the key being fetched

export function configure(config) {
  tileUrl = config && config.tile_url ? config.tile_url : null;
  $("#map-note").textContent = tileUrl ? "(map tiles + metric grid)" : "(offline metric grid)";
}

export function setTracks(view) {
  for (const [sn, points] of Object.entries(view.tracks || {})) tracks.set(sn, points.slice(-TRACK_POINTS));
  for (const point of Object.values(view.home || {})) if (!origin) origin = point;
}

function local([lat, lon]) {
  const rad = Math.PI / 180;
  return [(lon - origin[1]) * rad * R * Math.cos(origin[0] * rad), (lat - origin[0]) * rad * R];
}

function remember(sn, point, metric) {
  const list = tracks.get(sn) || [];
  const last = list[list.length - 1];
  const far = !last || (metric ? Math.hypot(last[0] - point[0], last[1] - point[1]) >= 0.5 : distance(last, point) >= 0.5);
  if (far) {
    list.push(point);
    if (list.length > TRACK_POINTS) list.shift();
  }
  tracks.set(sn, list);
}

function distance(a, b) {
  const rad = Math.PI / 180;
  const dy = (b[0] - a[0]) * rad * R;
  const dx = (b[1] - a[1]) * rad * R * Math.cos(a[0] * rad);
  return Math.hypot(dx, dy);
}

function niceStep(span) {
  const raw = span / 8;
  const pow = 10 ** Math.floor(Math.log10(raw));
  for (const m of [1, 2, 5, 10]) if (m * pow >= raw) return m * pow;
  return 10 * pow;
}

function targets(mission) {
  if (!mission || !mission.data) return [];
  const d = mission.data;
  if (mission.method === "takeoff_to_point" && typeof d.target_latitude === "number") return [[d.target_latitude, d.target_longitude]];
  if (Array.isArray(d.points)) return d.points.filter((p) => typeof p.latitude === "number").map((p) => [p.latitude, p.longitude]);
  return [];
}

function wantRoute(wayline) {
  const key = wayline && wayline.route;
  if (!key) return;
  if ((route && route.key === key) || routeAsked === key) return;
  routeAsked = key;
  get(`/api/wayline/${encodeURIComponent(wayline.flight_id)}`)
    .then((view) => {
      route = view;
      drawn = ""; // redraw with the route
    })
    .catch(() => {})
    .finally(() => {
      if (routeAsked === key) routeAsked = null;
    });
}

const live = (wayline) => ["sent", "in_progress", "paused"].includes(wayline.status);

function shownRoute(wayline) {
  return wayline && route && route.key === wayline.route ? route : null;
}

function drawRoute(svg, view, wayline, shown, aircraft) {
  const reached = wayline.reached || 0;
  const pts = shown.waypoints.map((w) => [w[0], view.px(local([w[1], w[2]]))]);
  const line = (list) => list.map(([, p]) => p.map((v) => v.toFixed(1)).join(",")).join(" ");
  const done = pts.filter(([i]) => i < reached);
  const todo = pts.filter(([i]) => i >= reached - 1);
  if (done.length > 1) svg.append(s("polyline", { points: line(done), class: "wayline done" }));
  if (todo.length > 1) svg.append(s("polyline", { points: line(todo), class: "wayline todo" }));
  const every = Math.max(1, Math.ceil(pts.length / LABELS));
  pts.forEach(([i, [x, y]], k) => {
    svg.append(s("circle", { cx: x, cy: y, r: 4, class: `waypoint ${i < reached ? "reached" : "remaining"}`, "data-index": i }));
    if (k % every === 0 || k === pts.length - 1) svg.append(s("text", { x: x + 6, y: y - 6, class: "waypoint-label", text: String(i + 1) }));
  });
  const next = shown.waypoints.find((w) => w[0] >= reached);
  if (next && aircraft && live(wayline)) {
    const [tx, ty] = view.px(local([next[1], next[2]]));
    const [ax, ay] = view.px(local([aircraft.osd.latitude, aircraft.osd.longitude]));
    svg.append(s("line", { x1: ax, y1: ay, x2: tx, y2: ty, class: "route" }), s("circle", { cx: tx, cy: ty, r: 8, class: "target" }));
    svg.dataset.waylineTarget = String(next[0]);
  } else delete svg.dataset.waylineTarget;
  const bp = wayline.break_point;
  if (bp && typeof bp.latitude === "number") {
    const [bx, by] = view.px(local([bp.latitude, bp.longitude]));
    svg.append(s("g", { transform: `translate(${bx.toFixed(1)},${by.toFixed(1)})`, class: "break-point" },
      s("rect", { x: -6, y: -6, width: 12, height: 12, class: "break-point" })),
    s("text", { x: bx + 9, y: by + 14, text: `break point (after ${bp.index})` }));
  }
  svg.dataset.waypoints = String(shown.total);
  svg.dataset.waypointsReached = String(reached);
}

function tileLayer(group, view) {
  const rad = Math.PI / 180;
  const lat0 = origin[0];
  const z = Math.max(0, Math.min(20, Math.round(Math.log2((2 * Math.PI * R * Math.cos(lat0 * rad)) / (256 * view.mpp)))));
  const n = 2 ** z;
  const toLatLon = ([x, y]) => [origin[0] + y / R / rad, origin[1] + x / (R * Math.cos(lat0 * rad)) / rad];
  const tileOf = ([lat, lon]) => [
    Math.floor(((lon + 180) / 360) * n),
    Math.floor(((1 - Math.log(Math.tan(lat * rad) + 1 / Math.cos(lat * rad)) / Math.PI) / 2) * n),
  ];
  const nw = tileOf(toLatLon([view.x0, view.y1]));
  const se = tileOf(toLatLon([view.x1, view.y0]));
  const cornerLat = (y) => Math.atan(Math.sinh(Math.PI * (1 - (2 * y) / n))) / rad;
  const cornerLon = (x) => (x / n) * 360 - 180;
  let count = 0;
  for (let x = nw[0]; x <= se[0] && count < 36; x++) {
    for (let y = nw[1]; y <= se[1] && count < 36; y++, count++) {
      const [ax, ay] = view.px(local([cornerLat(y), cornerLon(x)]));
      const [bx, by] = view.px(local([cornerLat(y + 1), cornerLon(x + 1)]));
      const href = tileUrl.replace("{z}", z).replace("{x}", x).replace("{y}", y);
      group.append(s("image", { href, x: ax, y: ay, width: bx - ax, height: by - ay, preserveAspectRatio: "none", opacity: 0.8 }));
    }
  }
}

function renderAircraftMap(state) {
  const svg = $("#map-svg");
  const aircraft = state.devices.filter((d) => d.osd && typeof d.osd.latitude === "number");
  for (const d of aircraft) {
    if (!origin) origin = d.home || [d.osd.latitude, d.osd.longitude];
    remember(d.sn, [d.osd.latitude, d.osd.longitude], false);
  }
  clear(svg);
  if (!origin) {
    svg.append(s("text", { x: 20, y: 30, text: "no aircraft position yet" }));
    return;
  }
  const wayline = state.wayline;
  wantRoute(wayline);
  const shown = shownRoute(wayline);
  const goals = wayline && live(wayline) ? [] : targets(state.mission);
  const pts = [[0, 0]];
  if (shown) for (const w of shown.waypoints) pts.push(local([w[1], w[2]]));
  for (const d of aircraft) {
    pts.push(local([d.osd.latitude, d.osd.longitude]));
    for (const p of tracks.get(d.sn) || []) pts.push(local(p));
  }
  for (const g of goals) pts.push(local(g));
  const xs = pts.map((p) => p[0]);
  const ys = pts.map((p) => p[1]);
  const cx = (Math.min(...xs) + Math.max(...xs)) / 2;
  const cy = (Math.min(...ys) + Math.max(...ys)) / 2;
  const span = Math.max(100, (Math.max(...xs) - Math.min(...xs)) * 1.3, (Math.max(...ys) - Math.min(...ys)) * 1.3 * (W / H));
  const mpp = span / W;
  const view = {
    mpp, x0: cx - (W / 2) * mpp, x1: cx + (W / 2) * mpp, y0: cy - (H / 2) * mpp, y1: cy + (H / 2) * mpp,
    px: ([x, y]) => [W / 2 + (x - cx) / mpp, H / 2 - (y - cy) / mpp],
  };
  if (tileUrl) tileLayer(svg.appendChild(s("g", { class: "tiles" })), view);
  const step = niceStep(span);
  const grid = s("g", {});
  for (let x = Math.ceil(view.x0 / step) * step; x <= view.x1; x += step) {
    const [px] = view.px([x, 0]);
    grid.append(s("line", { x1: px, y1: 0, x2: px, y2: H, class: Math.abs(x) < 1e-9 ? "grid-major" : "grid-line" }));
  }
  for (let y = Math.ceil(view.y0 / step) * step; y <= view.y1; y += step) {
    const [, py] = view.px([0, y]);
    grid.append(s("line", { x1: 0, y1: py, x2: W, y2: py, class: Math.abs(y) < 1e-9 ? "grid-major" : "grid-line" }));
  }
  svg.append(grid);
  svg.append(s("text", { x: 8, y: H - 8, text: `grid ${fmt(step, 0)} m · origin ${origin[0].toFixed(5)}, ${origin[1].toFixed(5)} · N ↑` }));
  const [hx, hy] = view.px([0, 0]);
  svg.append(s("circle", { cx: hx, cy: hy, r: 7, class: "home" }), s("text", { x: hx + 9, y: hy + 4, text: "H" }));
  for (const d of aircraft) {
    const trail = (tracks.get(d.sn) || []).map((p) => view.px(local(p)).map((v) => v.toFixed(1)).join(",")).join(" ");
    if (trail.includes(" ")) svg.append(s("polyline", { points: trail, class: "track" }));
  }
  if (shown) drawRoute(svg, view, wayline, shown, aircraft[0]);
  else {
    delete svg.dataset.waypoints;
    delete svg.dataset.waypointsReached;
  }
  let from = aircraft.length ? view.px(local([aircraft[0].osd.latitude, aircraft[0].osd.longitude])) : [hx, hy];
  for (const g of goals) {
    const [tx, ty] = view.px(local(g));
    svg.append(s("line", { x1: from[0], y1: from[1], x2: tx, y2: ty, class: "route" }));
    svg.append(s("circle", { cx: tx, cy: ty, r: 6, class: "target" }), s("line", { x1: tx - 10, y1: ty, x2: tx + 10, y2: ty, class: "target" }),
      s("line", { x1: tx, y1: ty - 10, x2: tx, y2: ty + 10, class: "target" }), s("text", { x: tx + 10, y: ty - 8, text: "target" }));
    from = [tx, ty];
  }
  for (const d of aircraft) {
    const [east, north] = local([d.osd.latitude, d.osd.longitude]);
    const [ax, ay] = view.px([east, north]);
    const heading = Number(d.osd.attitude_head || 0);
    svg.append(s("g", { transform: `translate(${ax.toFixed(1)},${ay.toFixed(1)}) rotate(${heading.toFixed(1)})`, class: "aircraft-mark" },
      s("path", { d: "M0,-12 L8,9 L0,4 L-8,9 Z", class: "aircraft" })));
    svg.append(s("text", { x: ax + 12, y: ay + 4, text: `${d.sn} ${fmt(d.osd.elevation)} m` }));
    svg.dataset.aircraftSn = d.sn;
    svg.dataset.aircraftNorth = north.toFixed(2);
    svg.dataset.aircraftEast = east.toFixed(2);
    svg.dataset.aircraftElevation = String(d.osd.elevation ?? "");
  }
}

function renderField(state) {
  const svg = clear($("#field-svg"));
  const k = 10;
  const ox = 20;
  const oy = 25;
  svg.append(s("rect", { x: ox, y: oy, width: FIELD.length * k, height: FIELD.width * k, class: "field" }));
  svg.append(s("line", { x1: ox + (FIELD.length * k) / 2, y1: oy, x2: ox + (FIELD.length * k) / 2, y2: oy + FIELD.width * k, class: "grid-major" }));
  svg.append(s("text", { x: ox, y: 15, text: `RoboMaster field ${FIELD.length} × ${FIELD.width} m` }));
  const robots = state.devices.filter((d) => d.osd && d.osd.x_position);
  for (const d of robots) {
    const p = [Number(d.osd.x_position.x), Number(d.osd.x_position.y)];
    remember(d.sn, p, true);
    const px = (q) => [ox + q[0] * k, oy + FIELD.width * k - q[1] * k];
    const trail = (tracks.get(d.sn) || []).map((q) => px(q).map((v) => v.toFixed(1)).join(",")).join(" ");
    if (trail.includes(" ")) svg.append(s("polyline", { points: trail, class: "track robot" }));
    const [x, y] = px(p);
    const heading = Number(d.osd.attitude_head || 0);
    svg.append(s("g", { transform: `translate(${x.toFixed(1)},${y.toFixed(1)}) rotate(${heading.toFixed(1)})` },
      s("circle", { r: 6, class: "robot" }), s("line", { x1: 0, y1: 0, x2: 0, y2: -11, class: "needle" })));
    svg.append(s("text", { x: x + 9, y: y - 6, text: `${d.sn} (${fmt(p[0])}, ${fmt(p[1])}) m` }));
    svg.dataset.robotX = String(p[0]);
    svg.dataset.robotY = String(p[1]);
  }
}

let drawn = "";

export function render(state) {
  const key = JSON.stringify([state.mission, state.wayline, route && route.key, state.devices.map((d) => d.osd && [d.osd.latitude, d.osd.longitude,
    d.osd.attitude_head, d.osd.elevation, d.osd.x_position, d.home])]);
  if (key === drawn) return;
  drawn = key;
  renderAircraftMap(state);
  renderField(state);
  const m = state.mission;
  const el = $("#mission");
  const w = state.wayline;
  if (w && (!m || live(w))) {
    const of = w.total ? ` · waypoint ${w.reached}/${w.total}` : "";
    const b = w.break_point;  // DJI's numbering: state 0 = on the segment that starts at waypoint index
    const bp = !b ? "" : b.state === 1 ? ` · break point at waypoint ${b.index}`
      : ` · break point after waypoint ${b.index} (${Math.round(b.progress * 100)} % of the way to the next)`;
    el.textContent = `wayline ${w.flight_id}: ${w.status} ${w.percent}%${of}${w.result ? ` · result ${w.result}` : ""}${bp}`;
    el.dataset.waylineStatus = w.status;
    el.dataset.waylinePercent = String(w.percent);
    return;
  }
  delete el.dataset.waylineStatus;
  if (!m) {
    el.textContent = "no fly-to or take-off target";
    return;
  }
  const p = m.progress;
  el.textContent = `${m.method} ${m.data.flight_id || m.data.fly_to_id || ""}: ${p ? `${p.status} (way point ${p.way_point_index}${p.result ? `, result ${p.result}` : ""})` : "accepted"}`;
}
