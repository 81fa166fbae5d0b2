// Actions panel: a form for every method the chosen device supports, generated from the contract's
// schemas; validated here, sent to the gateway (which validates again), with a confirmation first for
// anything that moves a device.
import { $, h, clear, toast } from "./dom.js";
import { send } from "./api.js";
import { build } from "./forms.js";
import { describe } from "./moves.js";

let catalog = null;
let reader = null;
let allowed = false;
let current = null; // {sn, method}
let latest = null; // the newest state push (the confirmation says how far from where a device is)

export function setState(state) {
  latest = state;
}

function osdOf(sn) {
  const device = latest && latest.devices ? latest.devices.find((d) => d.sn === sn) : null;
  if (device && device.osd) return device.osd;
  // the gateway's own methods (drc_mode_enter …): the aircraft's position
  const aircraft = latest && latest.devices ? latest.devices.find((d) => d.osd && typeof d.osd.latitude === "number") : null;
  return aircraft ? aircraft.osd : null;
}

function entries() {
  if (!catalog) return [];
  return [{ ...catalog.gateway, label: `${catalog.gateway.sn} (gateway)` }, ...catalog.devices.map((d) => ({ ...d, label: d.sn }))];
}

export function setCatalog(value) {
  catalog = value;
  const select = clear($("#action-device"));
  for (const e of entries()) select.append(h("option", { value: e.sn }, e.label));
  const first = catalog.devices[0];
  select.value = first ? first.sn : catalog.gateway.sn;
  showMethods();
}

export function setAllowed(value, session) {
  allowed = value;
  $("#action-send").disabled = !value;
  $("#actions-note").textContent = value
    ? "Sent as Cloud API services through the gateway's own dispatcher; every action is audited."
    : session && session.read_only
      ? "Read-only console: actions are refused (the emergency stop still works)."
      : session && !session.token_configured
        ? "No console.token is configured: actions are refused. Set DJIGW_CONSOLE__TOKEN to enable them."
        : "Sign in with the console token to send actions.";
}

function showMethods() {
  const entry = entries().find((e) => e.sn === $("#action-device").value);
  const select = clear($("#action-method"));
  for (const m of entry ? entry.methods : []) select.append(h("option", { value: m.method }, m.method));
  showForm();
}

function showForm() {
  const entry = entries().find((e) => e.sn === $("#action-device").value);
  const method = entry && entry.methods.find((m) => m.method === $("#action-method").value);
  if (!method) {
    clear($("#action-form"));
    reader = null;
    return;
  }
  current = { sn: entry.sn, method };
  $("#action-summary").textContent = method.summary || "";
  $("#action-moves").hidden = !method.moves;
  reader = build($("#action-form"), method.schema, entry.prefill);
}

export function ask(text) {
  const dialog = $("#confirm");
  $("#confirm-text").textContent = text;
  return new Promise((resolve) => {
    dialog.addEventListener("close", () => resolve(dialog.returnValue === "ok"), { once: true });
    dialog.showModal();
  });
}

async function submit() {
  if (!reader || !current) return;
  const { value, errors } = reader();
  if (errors.length) {
    $("#action-result").textContent = `not sent: ${errors.map((e) => `${e.path || "data"}: ${e.message}`).join("; ")}`;
    return;
  }
  const method = current.method;
  if (method.moves && !(await ask(`${describe(method.method, current.sn, value, osdOf(current.sn))} Send it?\n${JSON.stringify(value)}`))) {
    $("#action-result").textContent = "cancelled";
    return;
  }
  $("#action-result").textContent = `sending ${method.method} …`;
  $("#action-result").dataset.method = method.method;
  try {
    const out = await send("POST", "/api/action", { method: method.method, data: value, confirm: method.moves });
    $("#action-result").textContent = `${method.method}: result ${out.result}${out.output ? `\n${JSON.stringify(out.output, null, 2)}` : ""}`;
    $("#action-result").dataset.result = String(out.result);
    toast(`${method.method}: result ${out.result}`, out.result !== 0);
  } catch (err) {
    $("#action-result").textContent = `${method.method} refused (${err.status}): ${err.message}`;
    $("#action-result").dataset.result = `http ${err.status}`;
    toast(`${method.method} refused: ${err.message}`, true);
  }
}

export function init() {
  $("#action-device").addEventListener("change", showMethods);
  $("#action-method").addEventListener("change", showForm);
  $("#action-send").addEventListener("click", submit);
}
