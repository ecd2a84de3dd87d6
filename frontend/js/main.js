/** Boots the dashboard: theme, navigation, health indicator, auth prompt and the router. */
import { api, onUnauthorized, setToken } from "./api.js";
import { EVT, SEL, STORAGE } from "./constants.js";
import { h, icon, ICONS, qs, qsa, toast } from "./dom.js";
import { loadPlotly } from "./plot.js";
import { poll } from "./poll.js";
import { Router } from "./router.js";
import { loadScopes } from "./scopes.js";
import * as batches from "./views/batches.js";
import * as compare from "./views/compare.js";
import * as datasets from "./views/datasets.js";
import * as ecus from "./views/ecu/index.js";
import * as newRun from "./views/new-run/index.js";
import * as runLive from "./views/run/index.js";
import * as sweeps from "./views/sweeps.js";
import * as versions from "./views/versions.js";

/** The server's health (and version) in the sidebar is refreshed this often. */
const HEALTH_POLL_MS = 15000;

const ROUTES = [
  { path: /^\/$/, redirect: "/datasets" },
  { path: /^\/datasets\/?$/, view: datasets, section: "datasets" },
  { path: /^\/runs\/new\/?$/, view: newRun, section: "new-run" },
  { path: /^\/runs\/(\d+)\/?$/, keys: ["id"], view: runLive, section: "run" },
  { path: /^\/compare\/?$/, view: compare, section: "compare" },
  { path: /^\/sweeps\/?$/, view: sweeps, section: "sweeps" },
  { path: /^\/sweeps\/(\d+)\/?$/, keys: ["id"], view: sweeps, section: "sweeps" },
  { path: /^\/batches\/?$/, view: batches, section: "batches" },
  { path: /^\/batches\/(\d+)\/?$/, keys: ["id"], view: batches, section: "batches" },
  { path: /^\/versions\/?$/, view: versions, section: "versions" },
  { path: /^\/ecus\/?$/, view: ecus, section: "ecus" },
  { path: /^\/ecus\/(\d+)\/?$/, keys: ["id"], view: ecus, section: "ecus" },
];

function initTheme() {
  const stored = localStorage.getItem(STORAGE.theme);
  const prefersDark = window.matchMedia?.("(prefers-color-scheme: dark)").matches;
  applyTheme(stored || (prefersDark ? "dark" : "light"), false);
  qs(SEL.themeToggle).addEventListener("click", () => {
    const next = document.documentElement.dataset.theme === "dark" ? "light" : "dark";
    applyTheme(next, true);
  });
}

function applyTheme(name, persist) {
  document.documentElement.dataset.theme = name;
  qs(SEL.themeLabel).textContent = name === "dark" ? "Light theme" : "Dark theme";
  if (persist) localStorage.setItem(STORAGE.theme, name);
  window.dispatchEvent(new CustomEvent(EVT.themeChange, { detail: { theme: name } }));
}

function highlightNav(section) {
  for (const a of qsa(SEL.navLink)) {
    if (a.dataset.section && a.dataset.section === section) a.setAttribute("aria-current", "page");
    else a.removeAttribute("aria-current");
  }
}

/** The run a view shows is listed under the nav so one can jump back to it. */
function showCurrentRun(run) {
  const host = qs(SEL.currentRun);
  if (!run) return;
  host.hidden = false;
  host.replaceChildren(
    h("div", { class: "label" }, "Current run"),
    h(
      "a",
      { href: `/runs/${run.id}`, "data-nav": "", "data-section": "run" },
      icon(ICONS.play),
      `#${run.id} ${run.estimator}`,
    ),
  );
}

async function pollHealth() {
  const el = qs(SEL.health);
  try {
    const body = await api.get("/api/health");
    el.dataset.state = "ok";
    el.textContent = `${body.database ?? "online"}${body.version ? ` · v${body.version}` : ""}`;
  } catch {
    el.dataset.state = "down";
    el.textContent = "offline";
  }
}

function askForToken() {
  if (qs(SEL.tokenDialog)) return;
  const input = h("input", { type: "password", id: "token-input", autocomplete: "off" });
  const dialog = h(
    "dialog",
    { "data-token": "", "aria-labelledby": "token-title" },
    h(
      "form",
      { method: "dialog" },
      h("h2", { id: "token-title" }, "API token needed"),
      h(
        "p",
        { class: "help" },
        "This server requires a bearer token. It is kept in this browser only.",
      ),
      h("div", { class: "field" }, h("label", { for: "token-input" }, "Token"), input),
      h(
        "div",
        { class: "row end" },
        h("button", { value: "cancel", type: "submit" }, "Cancel"),
        h("button", { value: "ok", type: "submit", class: "primary" }, "Save"),
      ),
    ),
  );
  dialog.addEventListener("close", () => {
    if (dialog.returnValue === "ok" && input.value) {
      setToken(input.value.trim());
      window.location.reload();
    }
    dialog.remove();
  });
  document.body.append(dialog);
  dialog.showModal();
}

function boot() {
  initTheme();
  onUnauthorized(askForToken);
  loadScopes();
  window.addEventListener(EVT.currentRun, (e) => showCurrentRun(e.detail));
  const router = new Router(ROUTES, qs(SEL.main), { onChange: (section) => highlightNav(section) });
  // The first view is on screen before the browser spends its second on Plotly.js.
  const plots = () =>
    loadPlotly().catch((err) =>
      toast(`Plots are unavailable: ${err.message}`, { error: true, ms: 10000 }),
    );
  router.start().finally(() => requestAnimationFrame(() => setTimeout(plots, 0)));
  poll(
    null,
    async () => {
      await pollHealth();
      return true;
    },
    HEALTH_POLL_MS,
  );
}

boot();
