// Frame inspector: the last N frames of one device link, live, decoded by the gateway with the same code
// as `dji-gateway decode`; pause, filter by command and direction, select for hex and fields, download.
import { $, h, clear, time } from "./dom.js";

const SHOWN = 200; // rows drawn at once (the newest); all kept frames stay searchable
let keep = 500;
let records = [];
let sn = null;
let kind = null;
let paused = false;
let ask = () => {};
let known = "";
let selected = null;

export function configure(config, send) {
  keep = config.frames || keep;
  ask = send;
  $("#frame-link").addEventListener("change", (e) => select(e.target.value || null));
  $("#frame-pause").addEventListener("click", () => {
    paused = !paused;
    $("#frame-pause").textContent = paused ? "Resume" : "Pause";
    count(); // "· paused" shows at once (no frame arrives to redraw it while paused)
    ask({ type: "frames", sn: paused ? null : sn });
  });
  $("#frame-filter").addEventListener("input", draw);
  $("#frame-dir-rx").addEventListener("change", () => { draw(); link(); });
  $("#frame-dir-tx").addEventListener("change", () => { draw(); link(); });
}

function select(value) {
  sn = value;
  records = [];
  selected = null;
  draw();
  link();
  if (!paused) ask({ type: "frames", sn });
}

export function resubscribe() {
  if (sn && !paused) ask({ type: "frames", sn });
}

function link() {
  const a = $("#frame-download");
  if (!sn) {
    a.removeAttribute("href");
    return;
  }
  const dirs = [["rx", "#frame-dir-rx"], ["tx", "#frame-dir-tx"]].filter(([, q]) => $(q).checked).map(([d]) => d).join(",");
  const format = kind === "can" ? "candump" : "hex";
  a.href = `/api/frames/${encodeURIComponent(sn)}?format=${format}&dir=${dirs}`;
  a.textContent = kind === "can" ? "Download candump log" : "Download hex lines";
}

/** Offer the links of the devices in the latest state (once the list changes). */
export function links(devices) {
  const withLinks = devices.filter((d) => d.link).map((d) => d.sn);
  const key = withLinks.join(",");
  if (key === known) return;
  known = key;
  const select_ = $("#frame-link");
  clear(select_).append(h("option", { value: "" }, "(choose a link)"), ...devices.filter((d) => d.link).map((d) =>
    h("option", { value: d.sn }, `${d.sn} · ${d.link.kind} ${d.link.where}`)));
  if (sn) select_.value = sn;
}

export function add(msg) {
  if (msg.sn !== sn || paused) return;
  kind = msg.kind || kind;
  if (msg.reset) records = [];
  records.push(...msg.records);
  if (records.length > keep) records = records.slice(records.length - keep);
  link();
  if (msg.reset) draw();
  else prepend(msg.records);
}

/** New frames on top of the table (no redraw of what is there). */
function prepend(fresh) {
  const body = $("#frame-table tbody");
  const rows = fresh.filter(matches()).map(row).reverse();
  body.prepend(...rows);
  while (body.rows.length > SHOWN) body.deleteRow(body.rows.length - 1);
  count();
}

function count() {
  const shown = records.filter(matches()).length;
  $("#frame-count").textContent = sn ? `${shown} of ${records.length} frames kept (at most ${keep})${paused ? " · paused" : ""}` : "";
}

function matches() {
  const filter = $("#frame-filter").value.trim().toLowerCase();
  const dirs = { rx: $("#frame-dir-rx").checked, tx: $("#frame-dir-tx").checked };
  return (r) => dirs[r.dir] && (!filter || String(r.command || r.error || "").toLowerCase().includes(filter));
}

function summary(r) {
  if (!r.valid) return `bad frame: ${r.error}`;
  if (r.fields) return JSON.stringify(r.fields);
  return r.error || r.payload || "";
}

function row(r) {
  const tr = h("tr", { "data-command": r.command || "", "data-dir": r.dir, "data-n": r.n, class: selected === r.n ? "sel" : "" },
    h("td", { class: "mono" }, time(r.t * 1000)),
    h("td", {}, r.dir),
    h("td", { class: "mono" }, r.can_id == null ? "" : r.can_id.toString(16).toUpperCase()),
    h("td", { class: "mono" }, r.command || (r.valid ? "?" : "bad")),
    h("td", { class: "mono" }, r.seq ?? ""),
    h("td", { class: "mono fields" }, h("div", { class: "clamp" }, summary(r))));
  tr.addEventListener("click", () => {
    selected = r.n;
    for (const el of document.querySelectorAll("#frame-table tr.sel")) el.classList.remove("sel");
    tr.classList.add("sel");
    const hex = (r.hex || "").toUpperCase().match(/.{1,2}/g) || [];
    $("#frame-detail").textContent = `${r.dir} ${r.command || ""}\nhex: ${hex.join(" ")}\n\n${JSON.stringify(r, null, 2)}`;
  });
  return tr;
}

function draw() {
  const rows = records.filter(matches()).slice(-SHOWN).reverse();
  $("#frame-table tbody").replaceChildren(...rows.map(row));
  count();
}
