// Clock time for operators: UTC by default, local time on request (the timeline's
// UTC/local toggle, kept in localStorage). Times inside are UNIX seconds, UTC
// (docs/conventions.md); the console never shows session seconds alone.

const KEY = "demtrack.clock";
const listeners = new Set();

function stored() {
  try {
    return globalThis.localStorage?.getItem(KEY) === "local";
  } catch {
    return false;
  }
}

/** The display mode; `local` true shows the browser's local time with its UTC offset. */
export const clockMode = { local: stored() };

/** Call `fn` whenever the mode changes (the page redraws its times). */
export function onClockChange(fn) {
  listeners.add(fn);
}

export function setLocalClock(on) {
  clockMode.local = !!on;
  try {
    globalThis.localStorage?.setItem(KEY, clockMode.local ? "local" : "utc");
  } catch {
    /* private mode: the choice lasts for this page */
  }
  for (const fn of listeners) fn();
}

const pad = (n, w = 2) => String(n).padStart(w, "0");

/** The UTC offset of local time at UNIX second `t` (default now): "+01:00". */
function offsetText(t) {
  const d = new Date(Number.isFinite(t) ? t * 1000 : Date.now());
  const m = -d.getTimezoneOffset();
  const a = Math.abs(m);
  return `${m < 0 ? "-" : "+"}${pad(Math.floor(a / 60))}:${pad(a % 60)}`;
}

/** What the shown times are: "UTC", or "local (UTC+01:00)" at time `t`. */
export function zoneLabel(t) {
  return clockMode.local ? `local (UTC${offsetText(t)})` : "UTC";
}

/**
 * UNIX seconds `t` as clock time in the display mode: "HH:MM:SS.s" (`digits` decimals,
 * 0-3). `withDate` prefixes "YYYY-MM-DD " when the date is not 1970-01-01 (a session
 * replayed from t = 0); `date: true` always. The zone is not in the text: callers add
 * `zoneLabel(t)` (or use `fmtStamp`).
 */
export function fmtClock(t, { withDate = false, date = false, digits = 1 } = {}) {
  if (t === null || t === undefined || !Number.isFinite(t)) return "–";
  const d = new Date(Math.round(t * 1000));
  if (Number.isNaN(d.getTime())) return "–";
  const n = Math.max(0, Math.min(3, digits));
  const loc = clockMode.local;
  const Y = loc ? d.getFullYear() : d.getUTCFullYear();
  const M = (loc ? d.getMonth() : d.getUTCMonth()) + 1;
  const D = loc ? d.getDate() : d.getUTCDate();
  const h = loc ? d.getHours() : d.getUTCHours();
  const m = loc ? d.getMinutes() : d.getUTCMinutes();
  const s = loc ? d.getSeconds() : d.getUTCSeconds();
  const ms = d.getUTCMilliseconds(); // the same in every zone
  let text = `${pad(h)}:${pad(m)}:${pad(s)}`;
  if (n > 0) text += "." + pad(ms, 3).slice(0, n);
  const day = `${pad(Y, 4)}-${pad(M)}-${pad(D)}`;
  const epochDay = !loc && day === "1970-01-01";
  return date || (withDate && !epochDay) ? `${day} ${text}` : text;
}

/** A time with its date and zone, the way an operator reads it: "2026-12-01 14:32:05Z",
 * or "2026-12-01 15:32:05 +01:00" in local mode. */
export function fmtStamp(t, { digits = 0 } = {}) {
  const text = fmtClock(t, { date: true, digits });
  if (text === "–") return text;
  return clockMode.local ? `${text} ${offsetText(t)}` : `${text}Z`;
}
