/**
 * New run: dataset, one or several estimators (with description and paper), the columns that
 * feed their signals, the table grid, a config form generated from each estimator's schema,
 * and run options (pace, version cadence, gates). Starting several estimators at once checks
 * every form first, then opens the comparison of the new runs (of those the API accepted, when
 * it refuses one). Dataset, estimators, signals and axes live in the URL; the rest of the form
 * (breakpoints, start map, config values, pace, cadence, gates) is kept as a draft in
 * sessionStorage, so a reload shows the form as it was.
 */
import { api, clearErrors, estimators, scenarios, showError } from "../api.js";
import { PACES, SEL, SELECT, STORAGE } from "../constants.js";
import { card, debounce, fmt, fmtDuration, fmtInt, h, icon, ICONS, pageHead, toast, withUnit } from "../dom.js";
import { gridEditor } from "../grid-editor.js";
import { decodeSignals, encodeSignals, guessColumn, guessTable, KIND_TITLES, needsTable, rolesOf } from "../mapping.js";
import { schemaForm } from "../schema-form.js";

export const title = "New run";

/** Config properties filled from the signal mapping and the grid editor, not the form. */
const FROM_ELSEWHERE = new Set(["axes", "output", "output_unit", "locked"]);
/** Controls whose values a draft keeps (file inputs cannot be restored). */
const DRAFT_CONTROLS = "input:not([type=file]), select, textarea";
const DRAFT_SAVE_MS = 120;

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
  const state = {
    datasetId: Number(q.get("dataset")) || datasets[0]?.id || null,
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

  root.append(pageHead({ title: "New run", sub: "Pick data and estimators, set up the table, and watch the map adapt live." }));
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

  const section = (n, label, body, id) =>
    h("section", { class: "card", "aria-labelledby": id, "data-section": id },
      h("div", { class: "card-head" }, h("h2", { id, class: "section-title" }, h("span", { class: "n", "aria-hidden": "true" }, String(n)), label)),
      h("div", { class: "card-body" }, body));

  form.append(
    h("div", { class: "stack" },
      section(1, "Data", datasetHost, "sec-data"),
      section(2, "Estimators", estHost, "sec-est"),
      section(3, "Signals", signalsHost, "sec-signals"),
      tableSection,
      section(5, "Configuration", configHost, "sec-config"),
      section(6, "Run options", optionsHost, "sec-options"),
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
  datasetHost.append(h("div", { class: "field" }, h("label", { for: "run-dataset" }, "Dataset"), dsSelect, dsInfo));
  dsSelect.addEventListener("change", async () => {
    state.datasetId = Number(dsSelect.value);
    state.signals = {};
    state.axes = [];
    await loadDataset();
    syncUrl();
  });

  async function loadDataset() {
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
      h("p", { class: "help", style: { marginTop: 0 } }, "Tick several to run the same data through each and compare them."),
      ...groups.filter(([, list]) => list.length).map(([label, list]) =>
        h("fieldset", { style: { border: 0, padding: 0, margin: "0 0 12px" } },
          h("legend", { style: { padding: 0, marginBottom: "8px" } }, h("h3", {}, label)),
          h("div", { class: "est-grid" }, list.map((e) =>
            h("label", { class: `est${suggested.has(e.name) ? " suggested" : ""}`, for: `est-${e.name}`, dataset: { estimator: e.name } },
              h("input", { type: "checkbox", id: `est-${e.name}`, name: "estimator", value: e.name, checked: state.chosen.has(e.name),
                onchange: (ev) => {
                  if (ev.target.checked) state.chosen.add(e.name);
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
    submit.replaceChildren(icon(ICONS.play), ests.length > 1 ? `Start ${ests.length} runs` : "Start run");
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
    renderSignals();
    renderTable();
    renderConfig();
    renderGates();
  }

  function syncUrl() {
    const query = { dataset: state.datasetId, estimator: [...state.chosen].join(",") };
    const sig = encodeSignals(state.signals);
    if (sig) query.signals = sig;
    const axes = state.grid ? state.grid.snapshot().axes.map((a) => a.name) : state.axes;
    if (axes.length) query.axes = axes.join(",");
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
