// Forms from the contract's JSON Schemas (the same schemas `schemas/json/` exports) and the page-side
// validation of what was typed: types, required fields, ranges, enums, lengths, patterns, array sizes.
// The gateway validates again with the contract's models: this only saves a round trip.
import { h } from "./dom.js";

function resolve(schema, root) {
  let out = schema || {};
  for (let i = 0; i < 8 && out.$ref; i++) out = { ...root.$defs[out.$ref.split("/").pop()], ...without(out, "$ref") };
  if (Array.isArray(out.anyOf)) {
    const real = out.anyOf.filter((x) => x.type !== "null");
    if (real.length === 1) out = { ...resolve(real[0], root), ...without(out, "anyOf"), nullable: true };
  }
  if (Array.isArray(out.allOf) && out.allOf.length === 1) out = { ...resolve(out.allOf[0], root), ...without(out, "allOf") };
  return out;
}

function without(obj, key) {
  const copy = { ...obj };
  delete copy[key];
  return copy;
}

function typeOf(schema) {
  if (schema.enum) return "enum";
  if (Array.isArray(schema.type)) return schema.type.find((t) => t !== "null");
  return schema.type || (schema.properties ? "object" : "string");
}

function hint(schema) {
  const bits = [];
  if (schema.description) bits.push(schema.description.split("\n")[0]);
  const unit = schema["x-unit"];
  if (schema.minimum !== undefined || schema.maximum !== undefined) bits.push(`range ${schema.minimum ?? "…"} .. ${schema.maximum ?? "…"}${unit ? ` ${unit}` : ""}`);
  else if (unit) bits.push(unit);
  if (schema.exclusiveMinimum !== undefined) bits.push(`> ${schema.exclusiveMinimum}`);
  if (schema.pattern) bits.push(`pattern ${schema.pattern}`);
  return bits.join(" · ");
}

function field(container, name, schema, root, required, value, readers) {
  const s = resolve(schema, root);
  const t = typeOf(s);
  const label = `${s.title || name.split(".").pop()}${required ? " *" : ""}`;
  if (t === "object" && s.properties) {
    const set = h("fieldset", { "data-path": name }, h("legend", {}, label));
    container.append(set);
    const req = new Set(s.required || []);
    // inside an optional object nothing is filled in by default (a select offers "(not set)"): left
    // alone, the object is not sent at all; the validation still asks for its required fields once one is set
    for (const [key, sub] of Object.entries(s.properties)) {
      field(set, `${name}.${key}`, sub, root, required && req.has(key), value && typeof value === "object" ? value[key] : undefined, readers);
    }
    return;
  }
  const id = `f-${name.replace(/[^a-z0-9_]/gi, "-")}`;
  let input;
  let read;
  if (t === "enum") {
    input = h("select", { id, name });
    if (!required) input.append(h("option", { value: "" }, "(not set)"));
    s.enum.forEach((v, i) => input.append(h("option", { value: String(i) }, String(v))));
    const at = s.enum.findIndex((v) => v === (value ?? s.default));
    input.value = at >= 0 ? String(at) : required ? "0" : "";
    read = () => (input.value === "" ? undefined : s.enum[Number(input.value)]);
  } else if (t === "boolean") {
    input = h("select", { id, name });
    if (!required) input.append(h("option", { value: "" }, "(not set)"));
    input.append(h("option", { value: "false" }, "false"), h("option", { value: "true" }, "true"));
    const v = value ?? s.default;
    input.value = v === true ? "true" : v === false ? "false" : required ? "false" : "";
    read = () => (input.value === "" ? undefined : input.value === "true");
  } else if (t === "integer" || t === "number") {
    input = h("input", { id, name, type: "number", step: t === "integer" ? "1" : "any", min: s.minimum, max: s.maximum, inputmode: "decimal" });
    const v = value ?? s.default;
    if (v !== undefined && v !== null) input.value = String(v);
    read = () => {
      if (input.value.trim() === "") return undefined;
      const n = Number(input.value);
      return Number.isNaN(n) ? input.value : n;
    };
  } else if (t === "array" || t === "object") {
    input = h("textarea", { id, name, rows: 4, cols: 50, placeholder: t === "array" ? "[ … ] (JSON)" : "{ … } (JSON)" });
    const v = value ?? s.default;
    if (v !== undefined) input.value = JSON.stringify(v, null, 1);
    read = () => {
      if (input.value.trim() === "") return undefined;
      try {
        return JSON.parse(input.value);
      } catch {
        return { __invalid_json__: true };
      }
    };
  } else {
    const secret = s.format === "password" || s.writeOnly;
    input = h("input", { id, name, type: secret ? "password" : "text", maxlength: s.maxLength, autocomplete: "off" });
    const v = value ?? s.default;
    if (v !== undefined && v !== null) input.value = String(v);
    read = () => (input.value === "" && !required ? undefined : input.value);
  }
  container.append(h("label", { for: id }, label), input);
  const text = hint(s);
  if (text) container.append(h("div", { class: "hint" }, text));
  readers.push({ name, input, read, container });
}

/** Fill ``form`` with fields for ``schema``; returns read() -> {value, errors}. */
export function build(form, schema, prefill) {
  form.replaceChildren();
  const readers = [];
  const req = new Set(schema.required || []);
  const props = schema.properties || {};
  if (!Object.keys(props).length) form.append(h("p", { class: "muted" }, "no parameters"));
  for (const [key, sub] of Object.entries(props)) field(form, key, sub, schema, req.has(key), prefill ? prefill[key] : undefined, readers);
  return () => {
    for (const el of form.querySelectorAll(".error")) el.remove();
    for (const el of form.querySelectorAll(".invalid")) el.classList.remove("invalid");
    const value = {};
    for (const r of readers) {
      const v = r.read();
      if (v === undefined) continue;
      const path = r.name.split(".");
      let at = value;
      for (const p of path.slice(0, -1)) at = at[p] ??= {};
      at[path[path.length - 1]] = v;
    }
    const errors = validate(schema, value, schema, "");
    for (const e of errors) {
      const r = readers.find((x) => x.name === e.path) || readers.find((x) => x.name.startsWith(`${e.path}.`));
      if (r) {
        r.input.classList.add("invalid");
        r.input.insertAdjacentElement("afterend", h("div", { class: "error", "data-error-for": r.name }, e.message));
      }
    }
    return { value, errors };
  };
}

/** The JSON Schema rules the contract uses, checked on ``value``; a list of {path, message}. */
export function validate(schema, value, root, path) {
  const s = resolve(schema, root);
  const t = typeOf(s);
  const out = [];
  const err = (message) => out.push({ path, message });
  if (value === null && s.nullable) return out;
  if (value && value.__invalid_json__) return [{ path, message: "not valid JSON" }];
  if (t === "enum") {
    if (!s.enum.includes(value)) err(`one of ${s.enum.join(", ")}`);
    return out;
  }
  if (t === "object") {
    if (typeof value !== "object" || value === null || Array.isArray(value)) return [{ path, message: "an object" }];
    for (const key of s.required || []) if (value[key] === undefined) out.push({ path: path ? `${path}.${key}` : key, message: "required" });
    for (const [key, sub] of Object.entries(s.properties || {})) {
      if (value[key] !== undefined) out.push(...validate(sub, value[key], root, path ? `${path}.${key}` : key));
    }
    return out;
  }
  if (t === "array") {
    if (!Array.isArray(value)) return [{ path, message: "a JSON array" }];
    if (s.minItems !== undefined && value.length < s.minItems) err(`at least ${s.minItems} item(s)`);
    if (s.maxItems !== undefined && value.length > s.maxItems) err(`at most ${s.maxItems} item(s)`);
    if (s.items) value.forEach((item, i) => out.push(...validate(s.items, item, root, `${path}[${i}]`).map((e) => ({ ...e, path }))));
    return out;
  }
  if (t === "integer" || t === "number") {
    if (typeof value !== "number" || !Number.isFinite(value)) return [{ path, message: "a number" }];
    if (t === "integer" && !Number.isInteger(value)) err("a whole number");
    if (s.minimum !== undefined && value < s.minimum) err(`at least ${s.minimum}`);
    if (s.maximum !== undefined && value > s.maximum) err(`at most ${s.maximum}`);
    if (s.exclusiveMinimum !== undefined && value <= s.exclusiveMinimum) err(`more than ${s.exclusiveMinimum}`);
    if (s.exclusiveMaximum !== undefined && value >= s.exclusiveMaximum) err(`less than ${s.exclusiveMaximum}`);
    return out;
  }
  if (t === "boolean") {
    if (typeof value !== "boolean") err("true or false");
    return out;
  }
  if (typeof value !== "string") return [{ path, message: "text" }];
  if (s.minLength !== undefined && value.length < s.minLength) err(`at least ${s.minLength} character(s)`);
  if (s.maxLength !== undefined && value.length > s.maxLength) err(`at most ${s.maxLength} characters`);
  if (s.pattern && !new RegExp(s.pattern, "u").test(value)) err(`must match ${s.pattern}`);
  return out;
}
