// HTTP access to the console API with the operator token.
//
// The token comes from the page URL (`?token=...`, as `demtrack demo` prints it) or from the
// token form; it is kept in sessionStorage (this tab only) and removed from the address bar.
// Every request sends it as `Authorization: Bearer`; images are fetched the same way and
// shown from blob: URLs, so the token never sits in an <img> URL or a server log.

const KEY = "demtrack.token";

export class AuthError extends Error {}

export function takeTokenFromUrl() {
  const url = new URL(window.location.href);
  const t = url.searchParams.get("token");
  if (t) {
    sessionStorage.setItem(KEY, t);
    url.searchParams.delete("token");
    window.history.replaceState(null, "", url.pathname + url.search + url.hash);
  }
  return sessionStorage.getItem(KEY);
}

export function token() {
  return sessionStorage.getItem(KEY);
}

export function setToken(t) {
  sessionStorage.setItem(KEY, t);
}

function headers(extra) {
  const h = { ...(extra || {}) };
  const t = token();
  if (t) h.Authorization = `Bearer ${t}`;
  return h;
}

async function check(resp, what) {
  if (resp.status === 401) throw new AuthError("operator token required or wrong");
  if (!resp.ok) {
    let detail = resp.statusText;
    try {
      detail = (await resp.json()).detail || detail;
    } catch (_) {
      /* not JSON */
    }
    const err = new Error(`${what}: ${resp.status} ${detail}`);
    err.status = resp.status;
    err.detail = detail;
    throw err;
  }
  return resp;
}

export async function getJSON(path, { signal } = {}) {
  const resp = await fetch(path, { headers: headers(), signal });
  return (await check(resp, path)).json();
}

/** GET that answers null on 404 (optional endpoints another part of the server may add). */
export async function getOptionalJSON(path) {
  const resp = await fetch(path, { headers: headers() });
  if (resp.status === 404 || resp.status === 405) return null;
  return (await check(resp, path)).json();
}

export async function postJSON(path, body, { signal } = {}) {
  return sendJSON("POST", path, body, signal);
}

export async function putJSON(path, body, { signal } = {}) {
  return sendJSON("PUT", path, body, signal);
}

export async function deleteJSON(path, { signal } = {}) {
  const resp = await fetch(path, { method: "DELETE", headers: headers(), signal });
  return (await check(resp, path)).json();
}

async function sendJSON(method, path, body, signal) {
  const resp = await fetch(path, {
    method,
    headers: headers({ "Content-Type": "application/json" }),
    body: JSON.stringify(body),
    signal,
  });
  return (await check(resp, path)).json();
}

/** An image as a blob: URL (null on 404). */
export async function imageURL(path, { signal } = {}) {
  const resp = await fetch(path, { headers: headers(), signal });
  if (resp.status === 404) return null;
  const blob = await (await check(resp, path)).blob();
  return URL.createObjectURL(blob);
}

/** The stream's URL: resume after `since` (if any); `batch`: several messages per frame. */
export function wsURL(since, { batch = false } = {}) {
  const proto = window.location.protocol === "https:" ? "wss:" : "ws:";
  const q = new URLSearchParams({ token: token() || "" });
  if (since !== null && since !== undefined) q.set("since", String(since));
  if (batch) q.set("batch", "1");
  return `${proto}//${window.location.host}/ws?${q}`;
}
