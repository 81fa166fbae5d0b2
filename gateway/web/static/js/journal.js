// Log panel: the events, requests and replies the gateway sent and received, and the console's own actions.
import { $, h, time } from "./dom.js";

const KEEP = 300;

function detail(e) {
  if (e.dir === "console") {
    const parts = [e.who ? `by ${e.who}` : null, e.refused ? `refused: ${e.refused}` : null,
      e.output ? JSON.stringify(e.output) : null, e.stopped ? `stopped ${e.stopped.join(", ")}` : null];
    return parts.filter(Boolean).join(" · ");
  }
  return e.body || e.error || "";
}

export function add(entries) {
  const body = $("#log-table tbody");
  for (const e of entries) {
    const result = e.result ?? (e.refused ? "refused" : "");
    const row = h("tr", { "data-method": e.method || "", "data-kind": e.kind || "" },
      h("td", { class: "mono" }, time(e.t * 1000)),
      h("td", {}, e.dir === "up" ? "gateway →" : e.dir === "down" ? "→ gateway" : "console"),
      h("td", {}, e.kind || ""),
      h("td", { class: "mono" }, e.method || ""),
      h("td", { class: "mono" }, String(result)),
      h("td", { class: "mono fields" }, h("div", { class: "clamp", title: detail(e) }, detail(e))));
    body.prepend(row);
  }
  while (body.rows.length > KEEP) body.deleteRow(body.rows.length - 1);
}
