/**
 * New run: dataset, one or several estimators (with description and paper), the columns that
 * feed their signals, the table grid, a config form generated from each estimator's schema,
 * and run options (pace, version cadence, gates). Starting several estimators at once checks
 * every form first, then opens the comparison of the new runs (of those the API accepted, when
 * it refuses one). Dataset, estimators, signals and axes live in the URL; the rest of the form
 * (breakpoints, start map, config values, pace, cadence, gates) is kept as a draft in
 * sessionStorage, so a reload shows the form as it was.
 *
 * The same form starts a sweep (?mode=sweep: one estimator, the settings to vary picked from
 * its schema, each a list of values or a range drawn from, ranked by a metric) or a fleet
 * batch (?mode=batch&datasets=1,2,3: one configuration over several datasets); the API's
 * errors land next to the parameter ("parameters.sigma_v") or dataset ("dataset_ids[1]").
 */
import { api, clearErrors, estimators, scenarios, showError } from "../api.js";
import { PACES, SEL, SELECT, STORAGE } from "../constants.js";
import {
  card, debounce, fmt, fmtDuration, fmtInt, h, icon, ICONS, metricLabel, pageHead, parseNumberList, toast, withUnit,
} from "../dom.js";
import { gridEditor } from "../grid-editor.js";
import { decodeSignals, encodeSignals, guessColumn, guessTable, KIND_TITLES, needsTable, rolesOf } from "../mapping.js";
import { schemaForm, sweepableKeys } from "../schema-form.js";

export const title = "New run";

/** Config properties filled from the signal mapping and the grid editor, not the form. */
const FROM_ELSEWHERE = new Set(["axes", "output", "output_unit", "locked"]);
/** Controls whose values a draft keeps (file inputs cannot be restored). */
const DRAFT_CONTROLS = "input:not([type=file]), select, textarea";
const DRAFT_SAVE_MS = 120;

/** What the form starts: a run per estimator, a sweep of one estimator, or a batch over datasets. */
const MODES = Object.freeze([
  { value: "single", label: "Single run", title: "New run" },
  { value: "sweep", label: "Sweep", title: "New sweep" },
  { value: "batch", label: "Fleet batch", title: "New batch" },
]);
/** Ranking metrics offered per kind of estimator (the first is the default). */
const SWEEP_METRICS = Object.freeze({
  "table-filter": ["output_rmse", "rmse", "map_rmse", "max_abs_error", "mean_relative_error", "coverage"],
  "maf-observer": ["map_rmse", "output_rmse", "rmse"],
  torque: ["ise", "mae", "sd", "rmse"],
});
/** Metrics where bigger is better (ranked highest first by default). */
const HIGHER_BETTER = new Set(["coverage"]);
/** Settings a new sweep row offers first, when the estimator has them. */
const SWEEP_FIRST = ["sigma_w", "sigma_v", "p0", "forgetting", "mu", "gamma", "k"];

function fieldError(field, message) {
  return Object.assign(new Error(message), { field });
}

/** Remove a (dotted) key from a config object: the sweep sets it per run. */
function dropKey(config, key) {
  const parts = key.split(".");
  const last = parts.pop();
  const node = parts.reduce((n, k) => (n && typeof n === "object" ? n[k] : undefined), config);
  if (node && typeof node === "object") delete node[last];
}

/** A default of the catalog at a dotted key ("sensor.lag"), or undefined. */
function defaultAt(defaults, key) {
  return key.split(".").reduce((n, k) => (n && typeof n === "object" ? n[k] : undefined), defaults ?? {});
}

function loadDraft() {
  try {
    return JSON.parse(sessionStorage.getItem(STORAGE.newRunDraft) ?? "null");
  } catch {
    return null;
  }
}

/** {id: value | checked} of the controls in `container`. */
function controlValues(container) {
  const out = {};
  for (const el of container.querySelectorAll(DRAFT_CONTROLS)) {
    if (!el.id) continue;
    out[el.id] = el.type === "checkbox" || el.type === "radio" ? el.checked : el.value;
  }
  return out;
}

/** Put saved control values back; a "change" event lets dependent parts (switches) follow. */
function restoreControls(container, values) {
  for (const [id, value] of Object.entries(values ?? {})) {
    const el = container.querySelector(SELECT.id(id));
    if (!el) continue;
    if (el.type === "checkbox" || el.type === "radio") el.checked = Boolean(value);
    else el.value = String(value);
    el.dispatchEvent(new Event("change"));
  }
}

export async function mount(root, ctx) {
  const [catalog, datasets, baseMaps, scenarioList] = await Promise.all([
    estimators(),
    api.all("/api/datasets", { signal: ctx.signal }),
    api.all("/api/base-maps", { signal: ctx.signal }).catch(() => []),
    scenarios().catch(() => []),
  ]);
  const q = ctx.query;
  const batchIds = (q.get("datasets") ?? "").split(",").map(Number).filter((id) => datasets.some((d) => d.id === id));
  const state = {
    datasetId: Number(q.get("dataset")) || batchIds[0] || datasets[0]?.id || null,
    mode: MODES.some((m) => m.value === q.get("mode")) ? q.get("mode") : "single",
    batch: new Set(batchIds),
    sweep: { estimator: null, rows: [], samples: "", seed: "0", metric: "", order: "min" },
    chosen: new Set((q.get("estimator") ?? "").split(",").filter((n) => catalog.some((e) => e.name === n))),
    signals: decodeSignals(q.get("signals")),
    axes: (q.get("axes") ?? "").split(",").filter(Boolean),
    dataset: null,
    preview: null,
    forms: new Map(),
    grid: null,
    tab: null,
  };
  // The draft of this form from before a reload (same dataset only); each part is used once.
  const saved = loadDraft();
  const draft = saved && saved.datasetId === state.datasetId ? saved : null;
  if (draft?.sweep && typeof draft.sweep === "object" && Array.isArray(draft.sweep.rows)) {
    state.sweep = { ...state.sweep, ...draft.sweep, rows: draft.sweep.rows.filter((r) => r && typeof r.key === "string") };
  }
  if (state.mode !== "single" && state.chosen.size > 1) state.chosen = new Set([[...state.chosen][0]]);

  const modeButtons = MODES.map((m) => h("button", { type: "button", "data-mode": m.value, "aria-pressed": String(m.value === state.mode),
    onclick: () => setMode(m.value) }, m.label));
  const head = pageHead({
    title: MODES.find((m) => m.value === state.mode).title,
    sub: "Pick data and estimators, set up the table, and watch the map adapt live — or sweep settings, or run a fleet.",
    actions: datasets.length ? [h("div", { class: "seg mode-switch", role: "group", "aria-label": "What to start" }, modeButtons)] : [],
  });
  const heading = head.querySelector(SEL.pageTitle);
  root.append(head);
  if (!datasets.length) {
    root.append(card({ title: "No data yet", body: h("p", {}, "Upload a log or simulate a scenario first. ",
      h("a", { href: "/datasets" }, "Go to Datasets →")) }));
    return undefined;
  }

  const form = h("form", { novalidate: true, "aria-label": "New run", "data-run-form": "" });
  const datasetHost = h("div");
  const estHost = h("div");
  const signalsHost = h("div");
  const tableHost = h("div");
  const configHost = h("div");
  const optionsHost = h("div");
  const submit = h("button", { type: "submit", class: "primary", "data-start": "" }, icon(ICONS.play), "Start run");
  const formError = h("div", { class: "banner error", "data-form-error": "", hidden: true });
  const tableSection = h("div", { "data-table-section": "" });
  const sweepHost = h("div", { "data-sweep-form": "" });

  const section = (n, label, body, id) =>
    h("section", { class: "card", "aria-labelledby": id, "data-section": id },
      h("div", { class: "card-head" }, h("h2", { id, class: "section-title" }, h("span", { class: "n", "aria-hidden": "true" }, String(n)), label)),
      h("div", { class: "card-body" }, body));
  const sweepSection = section(6, "Sweep parameters", sweepHost, "sec-sweep");
  const optionsSection = section(6, "Run options", optionsHost, "sec-options");

  form.append(
    h("div", { class: "stack" },
      section(1, "Data", datasetHost, "sec-data"),
      section(2, "Estimators", estHost, "sec-est"),
      section(3, "Signals", signalsHost, "sec-signals"),
      tableSection,
      section(5, "Configuration", configHost, "sec-config"),
      sweepSection,
      optionsSection,
      formError,
      h("div", { class: "form-actions" }, h("a", { class: "button", href: "/datasets" }, "Cancel"), submit)),
  );
  tableSection.append(section(4, "Table grid", tableHost, "sec-table"));
  root.append(form);

  const selectedEstimators = () => catalog.filter((e) => state.chosen.has(e.name));
  const channels = () => (state.dataset?.channels ?? []).filter((c) => c.name !== state.dataset?.time_column);

  /* ---------- 1. dataset ---------- */
  const dsSelect = h("select", { id: "run-dataset", name: "dataset_id" },
    datasets.map((d) => h("option", { value: String(d.id), selected: d.id === state.datasetId }, `#${d.id} ${d.name} (${d.source})`)));
  const dsInfo = h("div", { class: "help" });
  const dsLabel = h("label", { for: "run-dataset" }, "Dataset");
  const batchList = h("div", { class: "batch-datasets" });
  const batchHost = h("div", { class: "field", "data-batch-datasets": "", "data-field": "dataset_ids", role: "group",
    "aria-labelledby": "batch-datasets-label" },
  h("div", { class: "label", id: "batch-datasets-label" }, "Datasets of the batch — one run each, merged into one map"),
  batchList);
  datasetHost.append(h("div", { class: "field" }, dsLabel, dsSelect, dsInfo), batchHost);
  dsSelect.addEventListener("change", async () => {
    state.datasetId = Number(dsSelect.value);
    state.signals = {};
    state.axes = [];
    await loadDataset();
    syncUrl();
  });

  async function loadDataset() {
    state.loading = true;
    state.dataset = datasets.find((d) => d.id === state.datasetId) ?? (await api.get(`/api/datasets/${state.datasetId}`));
    const d = state.dataset;
    dsInfo.textContent = `${fmtInt(d.rows)} rows at ${fmt(d.rate_hz, 3)} Hz (${fmtDuration(d.duration_s)}); channels: ` +
      (d.channels ?? []).map((c) => withUnit(c.name, c.unit)).join(", ");
    state.preview = await api.get(`/api/datasets/${d.id}/preview`, { query: { points: 400 }, signal: ctx.signal }).catch(() => null);
    if (!state.chosen.size) {
      const suggested = scenarioList.find((s) => s.name === d.scenario)?.estimators ?? [];
      const first = suggested.find((n) => catalog.some((e) => e.name === n)) ??
        (catalog.some((e) => e.name === "skf") ? "skf" : catalog[0]?.name);
      if (first) state.chosen.add(first);
    }
    state.loading = false;
    renderEstimators();
    renderAll();
  }

  /* ---------- 2. estimators ---------- */
  function renderEstimators() {
    const suggested = new Set(scenarioList.find((s) => s.name === state.dataset?.scenario)?.estimators ?? []);
    const groups = Object.entries(KIND_TITLES).map(([kind, label]) => [label, catalog.filter((e) => e.kind === kind)]);
    const other = catalog.filter((e) => !KIND_TITLES[e.kind]);
    if (other.length) groups.push(["Other", other]);
    estHost.replaceChildren(
      h("p", { class: "help", style: { marginTop: 0 } }, state.mode === "single"
        ? "Tick several to run the same data through each and compare them."
        : `A ${state.mode === "sweep" ? "sweep" : "batch"} runs one estimator: pick it.`),
      ...groups.filter(([, list]) => list.length).map(([label, list]) =>
        h("fieldset", { style: { border: 0, padding: 0, margin: "0 0 12px" } },
          h("legend", { style: { padding: 0, marginBottom: "8px" } }, h("h3", {}, label)),
          h("div", { class: "est-grid" }, list.map((e) =>
            h("label", { class: `est${suggested.has(e.name) ? " suggested" : ""}`, for: `est-${e.name}`, dataset: { estimator: e.name } },
              h("input", { type: state.mode === "single" ? "checkbox" : "radio", id: `est-${e.name}`, name: "estimator", value: e.name,
                checked: state.chosen.has(e.name),
                onchange: (ev) => {
                  // A sweep or batch runs one estimator: the boxes become radio buttons.
                  if (state.mode !== "single") state.chosen = new Set([e.name]);
                  else if (ev.target.checked) state.chosen.add(e.name);
                  else state.chosen.delete(e.name);
                  renderAll();
                  syncUrl();
                } }),
              h("div", { class: "t" }, e.title ?? e.name, h("code", { class: "tag" }, e.name)),
              h("div", { class: "d" }, e.description),
              e.paper ? h("div", { class: "p", title: e.paper }, shortPaper(e.paper)) : null))))),
    );
  }

  /* ---------- 3. signals ---------- */
  function renderSignals() {
    const chans = channels();
    const ests = selectedEstimators();
    const roles = new Map();
    for (const e of ests) for (const r of rolesOf(e)) if (!roles.has(r.role)) roles.set(r.role, r);
    if (ests.some((e) => e.kind === "table-filter") && !roles.has("y")) {
      roles.set("y", { role: "y", description: "Measured table output", unit: "" });
    }
    const taken = new Set();
    const guessY = guessTable(chans).y;
    const fields = [...roles.values()].map((r) => {
      let chosen = state.signals[r.role] ?? (r.role === "y" ? guessY : guessColumn(r, chans, taken));
      if (!chans.some((c) => c.name === chosen)) chosen = guessColumn(r, chans, taken);
      if (chosen) taken.add(chosen);
      state.signals[r.role] = chosen;
      const id = `sig-${r.role}`;
      const sel = h("select", { id, name: `signals.${r.role}` },
        chans.map((c) => h("option", { value: c.name, selected: c.name === chosen }, withUnit(c.name, c.unit))));
      sel.addEventListener("change", () => {
        state.signals[r.role] = sel.value;
        syncUrl();
      });
      return h("div", { class: "field" },
        h("label", { for: id }, r.role === "y" ? "Measured output y" : r.role, r.unit ? ` [${r.unit}]` : ""),
        sel, r.description ? h("div", { class: "help" }, r.description) : null);
    });
    signalsHost.replaceChildren(fields.length
      ? h("div", { class: "fields" }, fields)
      : h("p", { class: "help" }, ests.length ? "The selected estimators read their channels from the configuration below." : "Pick an estimator first."));
  }

  /* ---------- 4. table ---------- */
  function renderTable() {
    const show = selectedEstimators().some(needsTable);
    tableSection.hidden = !show;
    if (!show) return;
    const chans = channels();
    const wanted = state.axes.length ? state.axes : guessTable(chans).axes;
    if (state.grid && state.grid.datasetId === state.datasetId) return state.grid.redraw();
    state.grid?.destroy();
    const draftGrid = draft?.grid && sameNames(draft.grid.axes?.map((a) => a.name), wanted) ? draft.grid : null;
    if (draft) draft.grid = null;
    const g = gridEditor({ channels: chans, preview: state.preview, axes: wanted, baseMaps, saved: draftGrid,
      onChange: () => { syncUrl(); saveDraft(); } });
    g.datasetId = state.datasetId;
    state.grid = g;
    tableHost.replaceChildren(g.el);
  }

  /* ---------- 5. config ---------- */
  function renderConfig() {
    const ests = selectedEstimators();
    const keep = new Map();
    for (const e of ests) {
      const existing = state.forms.get(e.name);
      if (existing && existing.datasetId === state.datasetId) keep.set(e.name, existing);
      else {
        const hide = new Set([...FROM_ELSEWHERE, ...rolesOf(e).flatMap((r) => [r.role, `${r.role}_channel`])]);
        const f = schemaForm(e.config_schema ?? {}, { defaults: e.defaults ?? {}, hide, channels: channels(), idPrefix: `cfg-${e.name}` });
        f.datasetId = state.datasetId;
        f.panel = h("div", { role: "tabpanel", id: `panel-${e.name}`, "aria-labelledby": `tab-${e.name}`, "data-config": e.name },
          h("p", { class: "help", style: { marginTop: 0 } }, `${e.title}. Defaults follow ${e.paper ? shortPaper(e.paper) : "the paper"}.`),
          f.el);
        if (draft?.config?.[e.name]) {
          restoreControls(f.panel, draft.config[e.name]);
          delete draft.config[e.name];
        }
        keep.set(e.name, f);
      }
    }
    state.forms = keep;
    if (!ests.length) return configHost.replaceChildren(h("p", { class: "help" }, "Pick an estimator first."));
    if (!state.tab || !keep.has(state.tab)) state.tab = ests[0].name;
    const tabs = h("div", { class: "tabs", role: "tablist", "aria-label": "Estimator configuration" },
      ests.map((e) => h("button", { type: "button", role: "tab", id: `tab-${e.name}`, "aria-controls": `panel-${e.name}`,
        "aria-selected": String(e.name === state.tab), tabindex: e.name === state.tab ? "0" : "-1",
        onclick: () => selectTab(e.name),
        onkeydown: (ev) => {
          const i = ests.findIndex((x) => x.name === state.tab);
          if (ev.key === "ArrowRight") selectTab(ests[(i + 1) % ests.length].name, true);
          if (ev.key === "ArrowLeft") selectTab(ests[(i - 1 + ests.length) % ests.length].name, true);
        } }, e.name)));
    configHost.replaceChildren(ests.length > 1 ? tabs : h("div"), ...ests.map((e) => {
      const panel = keep.get(e.name).panel;
      panel.hidden = e.name !== state.tab;
      return panel;
    }));
    updateSubmit();
  }

  function updateSubmit() {
    const n = selectedEstimators().length;
    let text = n > 1 ? `Start ${n} runs` : "Start run";
    if (state.mode === "sweep") {
      const size = sweepSize().n;
      text = size ? `Start sweep (${size} run${size === 1 ? "" : "s"})` : "Start sweep";
    } else if (state.mode === "batch") {
      text = state.batch.size ? `Start batch (${state.batch.size} datasets)` : "Start batch";
    }
    submit.replaceChildren(icon(ICONS.play), text);
  }

  /* ---------- mode: single run, sweep or batch ---------- */
  function setMode(mode) {
    if (mode === state.mode) return;
    state.mode = mode;
    for (const b of modeButtons) b.setAttribute("aria-pressed", String(b.dataset.mode === mode));
    heading.textContent = MODES.find((m) => m.value === mode).title;
    if (mode !== "single" && state.chosen.size > 1) {
      state.chosen = new Set([state.chosen.has(state.tab) ? state.tab : [...state.chosen][0]]);
    }
    if (mode === "batch" && !state.batch.size && state.datasetId) state.batch.add(state.datasetId);
    syncUrl();
    // While the dataset (and its preview, which the grid is fitted to) loads, the form is not
    // drawn yet: the end of loadDataset draws it in the new mode.
    if (state.loading) return;
    clearErrors(form);
    renderEstimators();
    renderAll();
    saveDraft();
  }

  /* ---------- batch: the datasets ---------- */
  function renderBatch() {
    const on = state.mode === "batch";
    batchHost.hidden = !on;
    dsLabel.textContent = on ? "Channels, signals and grid from" : "Dataset";
    if (!on) return;
    batchList.replaceChildren(...datasets.map((d) => h("div", { class: "field" },
      h("label", { class: "check", for: `batch-ds-${d.id}` },
        h("input", { type: "checkbox", id: `batch-ds-${d.id}`, value: String(d.id), "data-batch-dataset": "", checked: state.batch.has(d.id),
          onchange: (e) => {
            if (e.target.checked) state.batch.add(d.id);
            else state.batch.delete(d.id);
            syncUrl();
            updateSubmit();
          } }),
        h("span", {}, `#${d.id} ${d.name}`, h("span", { class: "sub" }, ` · ${fmtInt(d.rows)} rows`))))));
  }

  /** The datasets of the batch (by id); each checkbox is tagged with its place so "dataset_ids[k]" errors find it. */
  function readBatch() {
    const ids = datasets.filter((d) => state.batch.has(d.id)).map((d) => d.id).sort((a, b) => a - b);
    for (const el of batchList.querySelectorAll("[data-batch-dataset]")) el.removeAttribute("data-field");
    ids.forEach((dsId, k) => batchList.querySelector(SELECT.id(`batch-ds-${dsId}`))?.setAttribute("data-field", `dataset_ids.${k}`));
    if (ids.length < 2) throw fieldError("dataset_ids", "Pick at least two datasets: a batch merges several vehicles' maps.");
    return ids;
  }

  /* ---------- sweep: the parameters ---------- */
  function sweepKeys(est) {
    const hide = new Set([...FROM_ELSEWHERE, ...rolesOf(est).flatMap((r) => [r.role, `${r.role}_channel`])]);
    return sweepableKeys(est.config_schema ?? {}, { hide });
  }

  const metricsFor = (est) => SWEEP_METRICS[est?.kind] ?? ["output_rmse", "rmse"];

  function newRow(keys) {
    const used = new Set(state.sweep.rows.map((r) => r.key));
    const free = keys.filter((k) => !used.has(k.key));
    const pick = SWEEP_FIRST.map((name) => free.find((k) => k.key === name)).find(Boolean) ?? free[0] ?? keys[0];
    return { key: pick.key, kind: "values", values: "", min: "", max: "", scale: "linear", integer: false };
  }

  /** How many runs the sweep will start (null while a range waits for a sample size) and why. */
  function sweepSize() {
    const sw = state.sweep;
    const samples = Number(sw.samples);
    if (String(sw.samples ?? "").trim() && Number.isInteger(samples) && samples > 0) {
      return { n: samples, text: `${samples} runs: random draws from the values and ranges (seed ${sw.seed || 0}).` };
    }
    if (!sw.rows.length) return { n: 0, text: "Add a parameter to sweep." };
    if (sw.rows.some((r) => r.kind === "range")) return { n: null, text: "A range is drawn from: give the number of samples." };
    const sizes = sw.rows.map((r) => String(r.values ?? "").split(/[\s,;]+/).filter(Boolean).length);
    const n = sizes.reduce((a, b) => a * b, 1);
    return { n, text: `${n} run${n === 1 ? "" : "s"}: the grid of ${sizes.join(" × ")} value${n === 1 ? "" : "s"}.` };
  }

  function renderSweep() {
    const on = state.mode === "sweep";
    sweepSection.hidden = !on;
    optionsSection.querySelector(".n").textContent = on ? "7" : "6";
    if (!on) return;
    const est = selectedEstimators()[0];
    const sw = state.sweep;
    if (!est) return sweepHost.replaceChildren(h("p", { class: "help" }, "Pick an estimator first."));
    const keys = sweepKeys(est);
    if (!keys.length) return sweepHost.replaceChildren(h("p", { class: "help" }, `${est.name} has no numeric settings to sweep.`));
    if (sw.estimator !== est.name) {
      sw.rows = sw.rows.filter((r) => keys.some((k) => k.key === r.key));
      if (!metricsFor(est).includes(sw.metric)) {
        sw.metric = metricsFor(est)[0];
        sw.order = HIGHER_BETTER.has(sw.metric) ? "max" : "min";
      }
      sw.estimator = est.name;
    }
    if (!sw.rows.length) sw.rows.push(newRow(keys));
    const count = h("p", { class: "sweep-count", "data-sweep-count": "", "aria-live": "polite" });
    const refresh = () => {
      count.textContent = sweepSize().text;
      updateSubmit();
    };
    const rows = sw.rows.map((row, k) => {
      const info = keys.find((x) => x.key === row.key) ?? keys[0];
      row.key = info.key;
      if (info.type === "enum") row.kind = "values";
      const field = `parameters.${row.key}`;
      const param = h("select", { id: `sweep-param-${k}`, onchange: (e) => {
        row.key = e.target.value;
        renderSweep();
        sweepHost.querySelector(SELECT.id(`sweep-param-${k}`))?.focus();
      } }, keys.map((x) => h("option", { value: x.key, selected: x.key === row.key }, `${x.label} · ${x.key}`)));
      const kind = h("select", { id: `sweep-kind-${k}`, disabled: info.type === "enum", onchange: (e) => {
        row.kind = e.target.value;
        renderSweep();
        sweepHost.querySelector(SELECT.id(`sweep-kind-${k}`))?.focus();
      } },
      h("option", { value: "values", selected: row.kind !== "range" }, "Values"),
      h("option", { value: "range", selected: row.kind === "range" }, "Range (random)"));
      const def = defaultAt(est.defaults, row.key);
      const about = [info.bounds, def !== undefined && def !== null && typeof def !== "object" ? `default ${def}` : ""].filter(Boolean).join(" · ");
      const set = (prop) => (e) => {
        row[prop] = e.target.type === "checkbox" ? e.target.checked : e.target.value;
        refresh();
      };
      let values;
      if (row.kind === "range") {
        const num = (prop, label, extra = {}) => h("div", { class: "field" },
          h("label", { for: `sweep-${prop}-${k}` }, label),
          h("input", { type: "number", step: "any", id: `sweep-${prop}-${k}`, name: `${field}.${prop}`, value: row[prop] ?? "",
            autocomplete: "off", oninput: set(prop), ...extra }));
        values = h("div", {},
          h("div", { class: "sweep-range" },
            num("min", "Min", { "data-field": field }),
            num("max", "Max"),
            h("div", { class: "field" }, h("label", { for: `sweep-scale-${k}` }, "Scale"),
              h("select", { id: `sweep-scale-${k}`, name: `${field}.scale`, onchange: set("scale") },
                h("option", { value: "linear", selected: row.scale !== "log" }, "linear"),
                h("option", { value: "log", selected: row.scale === "log" }, "log"))),
            h("label", { class: "check", for: `sweep-integer-${k}` },
              h("input", { type: "checkbox", id: `sweep-integer-${k}`, name: `${field}.integer`,
                checked: row.integer || info.type === "integer", disabled: info.type === "integer", onchange: set("integer") }),
              "integers")),
          about ? h("div", { class: "help" }, about) : null);
      } else {
        values = h("div", { class: "field" },
          h("label", { for: `sweep-values-${k}` }, "Values"),
          h("input", { type: "text", id: `sweep-values-${k}`, name: field, class: "mono", value: row.values ?? "", autocomplete: "off",
            inputmode: info.type === "enum" ? null : "decimal", oninput: set("values"),
            placeholder: info.type === "enum" ? info.options.join(", ") : "e.g. 0.5, 1, 2" }),
          h("div", { class: "help" }, info.type === "enum" ? `one or more of ${info.options.join(", ")}` : "comma-separated", about ? ` · ${about}` : ""));
      }
      return h("div", { class: "sweep-param", "data-sweep-row": k },
        h("div", { class: "field" }, h("label", { for: `sweep-param-${k}` }, "Parameter"), param),
        h("div", { class: "field" }, h("label", { for: `sweep-kind-${k}` }, "Give"), kind),
        values,
        h("button", { type: "button", class: "ghost icon", "aria-label": `Remove parameter ${k + 1}`, style: { marginTop: "22px" },
          onclick: () => {
            sw.rows.splice(k, 1);
            if (!sw.rows.length) sw.rows.push(newRow(keys));
            renderSweep();
            sweepHost.querySelector("[data-add-sweep-param]")?.focus();
          } }, icon(ICONS.x)));
    });
    const metrics = metricsFor(est);
    const metricSelect = h("select", { id: "sweep-metric", name: "metric", onchange: (e) => {
      sw.metric = e.target.value;
      sw.order = HIGHER_BETTER.has(sw.metric) ? "max" : "min";
      orderSelect.value = sw.order;
    } }, metrics.map((m) => h("option", { value: m, selected: m === sw.metric }, `${metricLabel(m)} (${m})`)));
    const orderSelect = h("select", { id: "sweep-order", name: "order", onchange: (e) => { sw.order = e.target.value; } },
      h("option", { value: "min", selected: sw.order !== "max" }, "Lowest first"),
      h("option", { value: "max", selected: sw.order === "max" }, "Highest first"));
    const all = keys.length <= sw.rows.length;
    sweepHost.replaceChildren(
      h("p", { class: "help", style: { marginTop: 0 } },
        "Every other setting is taken from the configuration above. Values make a grid (every combination); ",
        "ranges are drawn from at random — give the number of samples."),
      h("div", { class: "field", "data-field": "parameters" }, rows),
      h("button", { type: "button", class: "small", "data-add-sweep-param": "", disabled: all,
        onclick: () => {
          sw.rows.push(newRow(keys));
          renderSweep();
          sweepHost.querySelector(SELECT.id(`sweep-param-${sw.rows.length - 1}`))?.focus();
        } }, icon(ICONS.plus), "Add parameter"),
      count,
      h("div", { class: "fields" },
        h("div", { class: "field" }, h("label", { for: "sweep-samples" }, "Samples"),
          h("input", { type: "number", id: "sweep-samples", name: "samples", min: "1", step: "1", value: sw.samples ?? "",
            placeholder: "the full grid", autocomplete: "off", oninput: (e) => { sw.samples = e.target.value; refresh(); } }),
          h("div", { class: "help" }, "Random draws; empty: every combination of the values.")),
        h("div", { class: "field" }, h("label", { for: "sweep-seed" }, "Seed"),
          h("input", { type: "number", id: "sweep-seed", name: "seed", min: "0", step: "1", value: sw.seed ?? "0", autocomplete: "off",
            oninput: (e) => { sw.seed = e.target.value; refresh(); } })),
        h("div", { class: "field" }, h("label", { for: "sweep-metric" }, "Rank by"), metricSelect),
        h("div", { class: "field" }, h("label", { for: "sweep-order" }, "Best"), orderSelect)),
    );
    refresh();
  }

  /** The sweep part of the request: parameters, sample size and seed, metric and order. */
  function readSweep(est) {
    const keys = sweepKeys(est);
    const sw = state.sweep;
    const parameters = {};
    for (const row of sw.rows) {
      const info = keys.find((x) => x.key === row.key);
      const field = `parameters.${row.key}`;
      if (!info) throw fieldError(field, `${row.key} is not a setting of ${est.name}.`);
      if (row.key in parameters) throw fieldError(field, `${row.key} is swept twice: remove one of its rows.`);
      if (row.kind === "range") {
        const num = (prop) => {
          const raw = String(row[prop] ?? "").trim();
          const v = Number(raw);
          if (!raw || !Number.isFinite(v)) throw fieldError(`${field}.${prop}`, `Give the ${prop} of the range.`);
          return v;
        };
        parameters[row.key] = { min: num("min"), max: num("max"), scale: row.scale === "log" ? "log" : "linear",
          integer: Boolean(row.integer) || info.type === "integer" };
      } else {
        const raw = String(row.values ?? "").trim();
        if (!raw) throw fieldError(field, "Give the values to try, e.g. 0.5, 1, 2.");
        if (info.type === "enum") {
          parameters[row.key] = raw.split(/[\s,;]+/).filter(Boolean).map((v) => info.options.find((o) => String(o) === v) ?? v);
        } else {
          try {
            parameters[row.key] = parseNumberList(raw);
          } catch (err) {
            throw fieldError(field, err.message);
          }
        }
      }
    }
    if (!Object.keys(parameters).length) throw fieldError("parameters", "Add a parameter to sweep.");
    const out = { parameters, metric: sw.metric || metricsFor(est)[0], order: sw.order === "max" ? "max" : "min" };
    const samples = String(sw.samples ?? "").trim();
    if (samples) {
      const n = Number(samples);
      if (!Number.isInteger(n) || n < 1) throw fieldError("samples", "Give a whole number of samples (at least 1), or leave it empty for the grid.");
      out.samples = n;
    }
    const seed = String(sw.seed ?? "").trim();
    if (seed) {
      const n = Number(seed);
      if (!Number.isInteger(n) || n < 0) throw fieldError("seed", "The seed is a whole number ≥ 0.");
      out.seed = n;
    }
    return out;
  }

  function selectTab(name, focus = false) {
    state.tab = name;
    for (const b of configHost.querySelectorAll(SEL.tab)) {
      const on = b.id === `tab-${name}`;
      b.setAttribute("aria-selected", String(on));
      b.tabIndex = on ? 0 : -1;
      if (on && focus) b.focus();
    }
    for (const p of configHost.querySelectorAll(SEL.tabPanel)) p.hidden = p.dataset.config !== name;
  }

  /* ---------- 6. options ---------- */
  const runName = h("input", { type: "text", id: "run-name", name: "name", placeholder: "optional" });
  const pace = h("select", { id: "run-pace", name: "config.pace" }, PACES.map((p) => h("option", { value: p.value }, p.label)));
  const paceCustom = h("input", { type: "number", id: "run-pace-custom", min: "0.01", step: "any", value: "10", hidden: true,
    "aria-label": "Custom pace (real-time multiple)" });
  pace.addEventListener("change", () => { paceCustom.hidden = pace.value !== "custom"; });
  const cadence = h("select", { id: "run-cadence", name: "config.version_every" },
    h("option", { value: "" }, "Every 10 % of the log"),
    h("option", { value: "seconds" }, "Every N seconds of log"),
    h("option", { value: "samples" }, "Every N samples"));
  const cadenceN = h("input", { type: "number", id: "run-cadence-n", min: "1", step: "any", value: "10", hidden: true,
    "aria-label": "Version cadence N" });
  cadence.addEventListener("change", () => { cadenceN.hidden = !cadence.value; });
  const gatesHost = h("div", { class: "gates-editor" });
  const gates = [];
  if (draft) {
    runName.value = draft.options?.["run-name"] ?? "";
    for (const [el, id] of [[pace, "run-pace"], [paceCustom, "run-pace-custom"], [cadence, "run-cadence"], [cadenceN, "run-cadence-n"]]) {
      const v = draft.options?.[id];
      if (typeof v === "string" && v !== "") el.value = v;
    }
    paceCustom.hidden = pace.value !== "custom";
    cadenceN.hidden = !cadence.value;
    for (const g of draft.gates ?? []) if (g && typeof g === "object") gates.push({ ...g });
    if (draft.tab) state.tab = draft.tab;
  }

  function renderGates() {
    const chans = channels();
    gatesHost.replaceChildren(...gates.map((g, k) => {
      const pre = `config.gates.${k}`;
      const set = (key) => (e) => { g[key] = e.target.value; };
      const num = (key, label) => h("div", { class: "field", style: { margin: 0 } },
        h("label", { for: `gate-${k}-${key}` }, label),
        h("input", { type: "number", step: "any", id: `gate-${k}-${key}`, name: `${pre}.${key}`, value: g[key] ?? "", oninput: set(key) }));
      const type = h("select", { id: `gate-${k}-type`, name: `${pre}.type`, onchange: (e) => { g.type = e.target.value; renderGates(); } },
        ["range", "rate", "holdoff"].map((t) => h("option", { value: t, selected: t === g.type }, t)));
      const chan = h("select", { id: `gate-${k}-channel`, name: `${pre}.channel`, onchange: set("channel") },
        chans.map((c) => h("option", { value: c.name, selected: c.name === g.channel }, withUnit(c.name, c.unit))));
      g.channel = g.channel ?? chans[0]?.name;
      const params = g.type === "range" ? [num("min", "min"), num("max", "max"), h("div")]
        : g.type === "rate" ? [num("max_abs", "max |d/dt| per s"), h("div"), h("div")]
          : [h("div", { class: "field", style: { margin: 0 } }, h("label", { for: `gate-${k}-when` }, "when"),
            h("select", { id: `gate-${k}-when`, onchange: set("when") },
              h("option", { value: "below", selected: g.when !== "above" }, "below"),
              h("option", { value: "above", selected: g.when === "above" }, "above"))),
          num("threshold", "threshold"), num("seconds", "reject for [s]")];
      return h("div", { class: "gate-row", "data-gate": k },
        h("div", { class: "field", style: { margin: 0 } }, h("label", { for: `gate-${k}-type` }, "Gate"), type),
        h("div", { class: "field", style: { margin: 0 } }, h("label", { for: `gate-${k}-channel` }, "Channel"), chan),
        ...params,
        h("button", { type: "button", class: "ghost icon", "aria-label": `Remove gate ${k + 1}`,
          onclick: () => { gates.splice(k, 1); renderGates(); } }, icon(ICONS.x)));
    }));
  }

  optionsHost.append(
    h("div", { class: "fields" },
      h("div", { class: "field" }, h("label", { for: "run-name" }, "Run name"), runName),
      h("div", { class: "field" }, h("label", { for: "run-pace" }, "Pace"), pace, paceCustom,
        h("div", { class: "help" }, "Real-time multiple: replay a recorded cycle slowly enough to watch it adapt.")),
      h("div", { class: "field" }, h("label", { for: "run-cadence" }, "Keep a map version"), cadence, cadenceN)),
    h("div", { class: "label" }, "Sample gates"),
    h("p", { class: "help", style: { marginTop: 0 } }, "Reject samples outside a range, changing too fast, or shortly after an event."),
    gatesHost,
    h("button", { type: "button", class: "small", "data-add-gate": "", onclick: () => { gates.push({ type: "range" }); renderGates(); } },
      icon(ICONS.plus), "Add gate"),
  );

  function renderAll() {
    renderBatch();
    renderSignals();
    renderTable();
    renderConfig();
    renderSweep();
    renderGates();
    updateSubmit();
  }

  function syncUrl() {
    const query = { dataset: state.datasetId, estimator: [...state.chosen].join(",") };
    const sig = encodeSignals(state.signals);
    if (sig) query.signals = sig;
    const axes = state.grid ? state.grid.snapshot().axes.map((a) => a.name) : state.axes;
    if (axes.length) query.axes = axes.join(",");
    if (state.mode !== "single") query.mode = state.mode;
    if (state.mode === "batch" && state.batch.size) query.datasets = [...state.batch].sort((a, b) => a - b).join(",");
    ctx.setQuery(query);
  }

  /* ---------- draft (sessionStorage) ---------- */
  function draftNow() {
    const config = {};
    for (const [name, f] of state.forms) config[name] = controlValues(f.panel);
    return {
      datasetId: state.datasetId,
      grid: state.grid?.snapshot() ?? null,
      config,
      options: controlValues(optionsHost),
      gates: gates.map((g) => ({ ...g })),
      tab: state.tab,
      sweep: state.sweep,
    };
  }

  function saveDraft() {
    if (ctx.signal.aborted) return;
    try {
      sessionStorage.setItem(STORAGE.newRunDraft, JSON.stringify(draftNow()));
    } catch {
      /* storage full or disabled: the form simply starts afresh after a reload */
    }
  }
  const saveSoon = debounce(saveDraft, DRAFT_SAVE_MS);
  for (const type of ["input", "change", "click"]) form.addEventListener(type, saveSoon);
  window.addEventListener("pagehide", saveDraft);

  /* ---------- submit ---------- */
  function serviceOptions() {
    const out = {};
    if (pace.value === "custom") out.pace = Number(paceCustom.value);
    else if (pace.value !== "max") out.pace = Number(pace.value);
    if (cadence.value) out.version_every = { [cadence.value]: Number(cadenceN.value) };
    const gateList = gates.map((g) => {
      const num = (v) => (v === undefined || v === "" ? undefined : Number(v));
      if (g.type === "range") return { type: "range", channel: g.channel, min: num(g.min), max: num(g.max) };
      if (g.type === "rate") return { type: "rate", channel: g.channel, max_abs: num(g.max_abs) };
      return { type: "holdoff", channel: g.channel, [g.when === "above" ? "above" : "below"]: num(g.threshold), seconds: num(g.seconds) };
    });
    if (gateList.length) out.gates = gateList;
    return out;
  }

  function bodyFor(est, shared) {
    const f = state.forms.get(est.name);
    const config = { ...f.read(), ...shared.options };
    const signals = {};
    for (const r of rolesOf(est)) if (state.signals[r.role]) signals[r.role] = state.signals[r.role];
    if (est.kind === "table-filter" && state.signals.y) signals.y = state.signals.y;
    const body = { dataset_id: state.datasetId, estimator: est.name, signals, config };
    if (needsTable(est) && shared.grid) {
      body.table = shared.grid.table;
      if (shared.grid.base_map_id) body.base_map_id = shared.grid.base_map_id;
      if (shared.grid.locked) config.locked = shared.grid.locked;
      // Typed or imported start values replace the constant θ0 (the API keeps an explicit θ0).
      if (body.table.values || body.base_map_id) delete config.theta0;
    }
    const name = runName.value.trim();
    if (name) body.name = selectedEstimators().length > 1 ? `${name} · ${est.name}` : name;
    return body;
  }

  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    clearErrors(form);
    for (const b of configHost.querySelectorAll(SEL.tab)) b.removeAttribute("data-invalid");
    const ests = selectedEstimators();
    if (!ests.length) {
      showError(form, { message: "Pick at least one estimator.", field: "estimator" });
      return;
    }
    if (state.mode !== "single") {
      await submitGroup(ests[0]);
      return;
    }
    // Check every form before the first POST: all problems at once, each next to its field.
    const problems = [];
    let shared = null;
    try {
      shared = { options: serviceOptions(), grid: ests.some(needsTable) ? state.grid?.read() : null };
    } catch (err) {
      problems.push({ err, estimator: null });
    }
    const bodies = [];
    for (const est of ests) {
      try {
        if (shared) bodies.push(bodyFor(est, shared));
        else state.forms.get(est.name).read();
      } catch (err) {
        problems.push({ err, estimator: est.name });
      }
    }
    if (problems.length) {
      reportErrors(problems);
      return;
    }
    submit.disabled = true;
    const created = [];
    const failed = [];
    for (const body of bodies) {
      try {
        created.push({ run: await api.post("/api/runs", body), estimator: body.estimator });
      } catch (err) {
        if (err.name === "AbortError") return;
        failed.push({ err, estimator: body.estimator });
      }
    }
    submit.disabled = false;
    if (!created.length) {
      reportErrors(failed);
      return;
    }
    sessionStorage.removeItem(STORAGE.newRunDraft);
    window.removeEventListener("pagehide", saveDraft);
    if (failed.length) {
      // Some runs exist already: say which, and show those; the refusals travel in a toast.
      const started = created.map((c) => `#${c.run.id} ${c.estimator}`).join(", ");
      const refused = failed.map((f) => `${f.estimator}: ${f.err.message}`).join("; ");
      toast(`Started ${started}. Not started — ${refused}`, { error: true, ms: 15000 });
      ctx.navigate(`/compare?runs=${created.map((c) => c.run.id).join(",")}`);
      return;
    }
    if (created.length === 1) ctx.navigate(`/runs/${created[0].run.id}`);
    else ctx.navigate(`/compare?runs=${created.map((c) => c.run.id).join(",")}`);
  });

  /** Start a sweep or a batch: every part checked first, then one POST; on to its page. */
  async function submitGroup(est) {
    const problems = [];
    let body = null;
    let extra = null;
    try {
      body = bodyFor(est, { options: serviceOptions(), grid: needsTable(est) ? state.grid?.read() : null });
    } catch (err) {
      problems.push({ err, estimator: est.name });
    }
    if (body?.base_map_id) {
      problems.push({ err: fieldError("base_map_id", "Sweeps and batches start from a constant θ0 or typed start values, not a base map."),
        estimator: null });
    }
    try {
      extra = state.mode === "sweep" ? readSweep(est) : readBatch();
    } catch (err) {
      problems.push({ err, estimator: null });
    }
    if (problems.length) {
      reportErrors(problems);
      return;
    }
    const { base_map_id: _base, dataset_id: datasetId, ...common } = body;
    let path;
    let payload;
    if (state.mode === "sweep") {
      // A swept setting comes from its parameter, not the fixed configuration.
      for (const key of Object.keys(extra.parameters)) dropKey(common.config, key);
      path = "/api/sweeps";
      payload = { dataset_id: datasetId, ...common, ...extra };
    } else {
      path = "/api/batches";
      payload = { dataset_ids: extra, ...common };
    }
    submit.disabled = true;
    let group;
    try {
      group = await api.post(path, payload);
    } catch (err) {
      submit.disabled = false;
      if (err.name === "AbortError") return;
      reportErrors([{ err, estimator: est.name }]);
      return;
    }
    submit.disabled = false;
    sessionStorage.removeItem(STORAGE.newRunDraft);
    window.removeEventListener("pagehide", saveDraft);
    ctx.navigate(`/${state.mode === "sweep" ? "sweeps" : "batches"}/${group.id}`);
  }

  /**
   * Show every problem next to its field. Estimators with a config problem get their tab marked;
   * the open tab stays open if it has one, else the first such tab opens.
   */
  function reportErrors(problems) {
    const several = selectedEstimators().length > 1;
    let firstTab = null;
    for (const { err, estimator } of problems) {
      const field = err.field ?? "";
      const inConfig = field.startsWith("config") && !/^config\.(pace|version_every|gates)/.test(field);
      if (inConfig && estimator && state.forms.has(estimator)) {
        if (firstTab === null || estimator === state.tab) firstTab = estimator;
        configHost.querySelector(SELECT.id(`tab-${estimator}`))?.setAttribute("data-invalid", "");
        showError(state.forms.get(estimator).panel, err);
      } else {
        showError(form, estimator && several ? Object.assign(err, { message: `${estimator}: ${err.message}` }) : err);
      }
    }
    if (firstTab) {
      selectTab(firstTab);
      state.forms.get(firstTab).panel.querySelector(SEL.invalid)?.focus();
    }
  }

  await loadDataset();
  return () => {
    window.removeEventListener("pagehide", saveDraft);
    state.grid?.destroy();
  };
}

function sameNames(a, b) {
  return Array.isArray(a) && a.length === b.length && a.every((x, i) => x === b[i]);
}

/** "Guardiola, Pla, … (2014), Control Eng. Practice — the SKF paper" → "Guardiola et al. (2014) · the SKF paper". */
function shortPaper(paper) {
  const m = /^([^,(&]+)[^(]*\((\d{4})\)/.exec(paper);
  if (!m) return paper.length > 80 ? `${paper.slice(0, 77)}…` : paper;
  const many = /,|&| and /.test(paper.slice(0, paper.indexOf("(")));
  const nick = /—\s*(.+)$/.exec(paper)?.[1];
  return `${m[1].trim()}${many ? " et al." : ""} (${m[2]})${nick ? ` · ${nick}` : ""}`;
}
