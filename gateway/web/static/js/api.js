// The console's HTTP calls: JSON in and out, the CSRF token of the sign-in session on every change.
let csrf = null;

export class HttpError extends Error {
  constructor(status, message) {
    super(message);
    this.status = status;
  }
}

export function setCsrf(value) {
  csrf = value;
}

/** The sign-in session's CSRF token (live control sends it with each WebSocket message). */
export function csrfToken() {
  return csrf;
}

async function parse(response) {
  let body = null;
  try {
    body = await response.json();
  } catch {
    body = null;
  }
  if (!response.ok) throw new HttpError(response.status, (body && body.error) || response.statusText);
  return body;
}

//: a request the gateway has not answered in this long is given up (the page's start retries): a start
//: waiting for ever on one lost response left a page "connecting" with no rows (seen in a loaded CI run)
const GET_TIMEOUT_MS = 8000;

export async function get(path) {
  return parse(await fetch(path, { credentials: "same-origin", cache: "no-store", signal: AbortSignal.timeout(GET_TIMEOUT_MS) }));
}

export async function send(method, path, body) {
  const headers = { "Content-Type": "application/json" };
  if (csrf) headers["X-CSRF-Token"] = csrf;
  const init = { method, headers, credentials: "same-origin" };
  if (body !== undefined) init.body = JSON.stringify(body);
  return parse(await fetch(path, init));
}
