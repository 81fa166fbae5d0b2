// Cloud control: the request waiting for the operator (Accept / Deny before its deadline: no answer denies),
// who holds cloud control (Revoke). The answers are actions: they need the console token.
import { $, fmt, toast } from "./dom.js";
import { send } from "./api.js";

let shown = null; // the waiting request's user_id the buttons answer (never one that replaced it)

async function decide(decision) {
  try {
    const out = await send("POST", "/api/cloud-control", { decision, user_id: decision === "revoke" ? undefined : shown });
    toast(`cloud control: ${decision} done`);
    render(out.cloud_control);
  } catch (err) {
    toast(`cloud control ${decision} refused: ${err.message}${err.status === 401 ? " (sign in first)" : ""}`, true);
  }
}

export function init() {
  $("#cc-accept").addEventListener("click", () => decide("accept"));
  $("#cc-deny").addEventListener("click", () => decide("deny"));
  $("#cc-revoke").addEventListener("click", () => decide("revoke"));
}

export function render(cc) {
  const panel = $("#cloud-control");
  if (!cc || (!cc.in_force && !cc.pending && !cc.holder)) {
    panel.hidden = true;
    return;
  }
  panel.hidden = false;
  const waiting = cc.pending;
  $("#cc-request").hidden = !waiting;
  panel.dataset.pending = waiting ? waiting.user_id : "";
  panel.dataset.holder = cc.holder ? cc.holder.user_id : "";
  if (waiting) {
    shown = waiting.user_id;
    $("#cc-callsign").textContent = waiting.user_callsign;
    $("#cc-user").textContent = `(${waiting.user_id})`;
    $("#cc-left").textContent = `denied in ${fmt(waiting.left_s, 0)} s without an answer`;
  } else {
    shown = null;
  }
  $("#cc-holder").textContent = cc.holder
    ? `held by ${cc.holder.user_callsign} (${cc.holder.user_id}), granted by the ${cc.holder.by} ${fmt(cc.holder.held_s, 0)} s ago`
    : "nobody holds cloud control: live control is refused until a request is accepted";
  $("#cc-revoke").hidden = !cc.holder;
}
