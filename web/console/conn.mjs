// The connection pill and banner in the top bar, and the operator-token dialog.

import * as api from "./api.mjs";
import { $ } from "./util.mjs";

/** Shows the stream's state ("live", "reconnecting", "unauthorized", ...). */
export function setConn(state, detail) {
  const pill = $("#conn");
  pill.dataset.state = state;
  pill.textContent = { live: "connected", reconnecting: "reconnecting…" }[state] || state;
  pill.title = detail || "live stream";
  $("#banner").classList.toggle("hidden", state !== "reconnecting");
  if (state === "unauthorized") askToken("the server refused the token");
}

/** Opens the token dialog, saying why. */
export function askToken(why) {
  const dlg = $("#token-dialog");
  $("#token-error").textContent = why || "";
  if (!dlg.open) dlg.showModal();
}

/** The dialog's form keeps the token for this tab and reloads the page with it. */
export function wireTokenForm() {
  $("#token-form").addEventListener("submit", (ev) => {
    const v = $("#token-input").value.trim();
    if (!v) {
      ev.preventDefault();
      return;
    }
    api.setToken(v);
    window.location.reload();
  });
}
