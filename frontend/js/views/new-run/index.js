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
 *
 * The parts: picker.js (dataset, estimators, signals), grid.js, config-form.js, sweep-form.js
 * and sweep-request.js, batch-form.js, options.js and gates.js, draft.js, submit.js; state.js
 * describes the `view` they share.
 */
import { api, clearErrors, estimators, scenarios } from "../../api.js";
import { SEL } from "../../constants.js";
import { card, h, icon, ICONS, pageHead } from "../../dom.js";
import { encodeSignals } from "../../mapping.js";
import { SCOPE } from "../../scopes.js";
import { batchPicker, renderBatch } from "./batch-form.js";
import { renderConfig, selectTab } from "./config-form.js";
import { draftKeeper, takeDraft } from "./draft.js";
import { ecuFromQuery, renderEcuBanner } from "./ecu-prefill.js";
import { renderTable } from "./grid.js";
import { runOptions } from "./options.js";
import { datasetPicker, loadDataset, renderEstimators, renderSignals } from "./picker.js";
import { initialState, MODES, selectedEstimators } from "./state.js";
import { submitForm } from "./submit.js";
import { renderSweep } from "./sweep-form.js";
import { sweepSize } from "./sweep-request.js";

export const title = "New run";

export async function mount(root, ctx) {
  const [catalog, datasets, baseMaps, scenarioList] = await Promise.all([
    estimators(),
    api.all("/api/datasets", { signal: ctx.signal }),
    api.all("/api/base-maps", { signal: ctx.signal }).catch(() => []),
    scenarios().catch(() => []),
  ]);
  const state = initialState(ctx.query, catalog, datasets);
  // "Run again…" (/runs/new?from=RUN_ID): that run's dataset, estimator, signals, grid and
  // configuration fill the form (setup.js), ready to change.
  const fromRun = await runToReuse(ctx, state, catalog);
  // The draft of this form from before a reload (same dataset only); each part is used once.
  const draft = fromRun ? null : takeDraft(state);
  const view = { ctx, catalog, datasets, baseMaps, scenarioList, state, draft, fromRun };
  // "Adapt this map" of the ECU view: the table comes from the A2L (ecu-prefill.js).
  view.ecu = ecuFromQuery(ctx.query);
  view.renderAll = () => renderAll(view);
  view.syncUrl = () => syncUrl(view);
  view.updateSubmit = () => updateSubmit(view);
  view.selectTab = (name, focus) => selectTab(view, name, focus);

  view.modeButtons = MODES.map((m) =>
    h(
      "button",
      {
        type: "button",
        "data-mode": m.value,
        "aria-pressed": String(m.value === state.mode),
        onclick: () => setMode(view, m.value),
      },
      m.label,
    ),
  );
  const head = pageHead({
    title: MODES.find((m) => m.value === state.mode).title,
    sub: "Pick data and estimators, set up the table, and watch the map adapt live — or sweep settings, or run a fleet.",
    actions: datasets.length
      ? [
          h(
            "div",
            { class: "seg mode-switch", role: "group", "aria-label": "What to start" },
            view.modeButtons,
          ),
        ]
      : [],
  });
  view.heading = head.querySelector(SEL.pageTitle);
  root.append(head);
  if (!datasets.length) {
    const body = h(
      "p",
      {},
      "Upload a log or simulate a scenario first. ",
      h("a", { href: "/datasets" }, "Go to Datasets →"),
    );
    root.append(card({ title: "No data yet", body }));
    return undefined;
  }

  root.append(buildForm(view));
  if (draft?.tab) state.tab = draft.tab;
  view.drafts = draftKeeper(view);
  view.saveDraft = view.drafts.save;
  view.form.addEventListener("submit", (e) => submitForm(view, e));

  await loadDataset(view);
  return () => {
    view.drafts.stop();
    state.grid?.destroy();
  };
}

/** The run of ?from=RUN_ID, its choices put into the state; null without (or if it is gone). */
async function runToReuse(ctx, state, catalog) {
  const id = Number(ctx.query.get("from"));
  if (!Number.isInteger(id) || id < 1) return null;
  const run = await api.get(`/api/runs/${id}`, { signal: ctx.signal }).catch(() => null);
  if (!run || !catalog.some((e) => e.name === run.estimator)) return null;
  state.datasetId = run.dataset_id;
  state.mode = "single";
  state.chosen = new Set([run.estimator]);
  state.signals = { ...(run.signals ?? {}) };
  state.axes = (run.table?.axes ?? []).map((a) => a.name);
  return run;
}

/** A numbered section card of the form. */
function section(n, label, body, id) {
  return h(
    "section",
    { class: "card", "aria-labelledby": id, "data-section": id },
    h(
      "div",
      { class: "card-head" },
      h(
        "h2",
        { id, class: "section-title" },
        h("span", { class: "n", "aria-hidden": "true" }, String(n)),
        label,
      ),
    ),
    h("div", { class: "card-body" }, body),
  );
}

/** The form's sections, with empty hosts the parts draw into; the options built at once. */
function buildForm(view) {
  const hosts = {
    dataset: h("div"),
    estimators: h("div"),
    signals: h("div"),
    table: h("div"),
    config: h("div"),
    sweep: h("div", { "data-sweep-form": "" }),
    tableSection: h("div", { "data-table-section": "" }),
    ecu: h("div", { "data-ecu-prefill": "" }),
  };
  view.hosts = hosts;
  view.datasetPicker = datasetPicker(view);
  view.batch = batchPicker();
  hosts.dataset.append(view.datasetPicker.el, view.batch.el);
  view.options = runOptions(view);
  hosts.sweepSection = section(6, "Sweep parameters", hosts.sweep, "sec-sweep");
  hosts.optionsSection = section(6, "Run options", view.options.el, "sec-options");
  hosts.tableSection.append(section(4, "Table grid", hosts.table, "sec-table"));
  view.submit = h(
    "button",
    { type: "submit", class: "primary", "data-start": "", "data-needs": SCOPE.run },
    icon(ICONS.play),
    "Start run",
  );
  view.form = h(
    "form",
    { novalidate: true, "aria-label": "New run", "data-run-form": "" },
    h(
      "div",
      { class: "stack" },
      hosts.ecu,
      section(1, "Data", hosts.dataset, "sec-data"),
      section(2, "Estimators", hosts.estimators, "sec-est"),
      section(3, "Signals", hosts.signals, "sec-signals"),
      hosts.tableSection,
      section(5, "Configuration", hosts.config, "sec-config"),
      hosts.sweepSection,
      hosts.optionsSection,
      h("div", { class: "banner error", "data-form-error": "", hidden: true }),
      h(
        "div",
        { class: "form-actions" },
        h("a", { class: "button", href: "/datasets" }, "Cancel"),
        view.submit,
      ),
    ),
  );
  return view.form;
}

function renderAll(view) {
  renderBatch(view);
  renderSignals(view);
  renderTable(view);
  renderEcuBanner(view);
  renderConfig(view);
  renderSweep(view);
  view.options.gates.render();
  view.options.renderRaster();
  updateSubmit(view);
}

/** The start button says what it starts: runs, a sweep of n runs, a batch over n datasets. */
function updateSubmit(view) {
  const { state } = view;
  const n = selectedEstimators(view).length;
  let text = n > 1 ? `Start ${n} runs` : "Start run";
  if (state.mode === "sweep") {
    const size = sweepSize(state.sweep).n;
    text = size ? `Start sweep (${size} run${size === 1 ? "" : "s"})` : "Start sweep";
  } else if (state.mode === "batch") {
    text = state.batch.size ? `Start batch (${state.batch.size} datasets)` : "Start batch";
  }
  view.submit.replaceChildren(icon(ICONS.play), text);
}

/** Switch between a single run, a sweep and a batch (which run one estimator). */
function setMode(view, mode) {
  const { state } = view;
  if (mode === state.mode) return;
  state.mode = mode;
  for (const b of view.modeButtons) b.setAttribute("aria-pressed", String(b.dataset.mode === mode));
  view.heading.textContent = MODES.find((m) => m.value === mode).title;
  if (mode !== "single" && state.chosen.size > 1) {
    state.chosen = new Set([state.chosen.has(state.tab) ? state.tab : [...state.chosen][0]]);
  }
  if (mode === "batch" && !state.batch.size && state.datasetId) state.batch.add(state.datasetId);
  syncUrl(view);
  // While the dataset (and its preview, which the grid is fitted to) loads, the form is not
  // drawn yet: the end of loadDataset draws it in the new mode.
  if (state.loading) return;
  clearErrors(view.form);
  renderEstimators(view);
  renderAll(view);
  view.saveDraft();
}

/**
 * Dataset, estimators, signals, axes, mode and batch datasets into the URL; nothing once the
 * view is left (a dataset's load can end after the user moved on, and would write this
 * form's query onto the next page's URL).
 */
function syncUrl(view) {
  if (view.ctx.signal.aborted) return;
  const { state } = view;
  const query = { dataset: state.datasetId, estimator: [...state.chosen].join(",") };
  const sig = encodeSignals(state.signals);
  if (sig) query.signals = sig;
  const axes = state.grid ? state.grid.snapshot().axes.map((a) => a.name) : state.axes;
  if (axes.length) query.axes = axes.join(",");
  if (state.mode !== "single") query.mode = state.mode;
  if (view.fromRun) query.from = view.fromRun.id;
  if (!state.useSetup) query.setup = "off";
  if (view.ecu) Object.assign(query, { ecu: view.ecu.ecuId, map: view.ecu.map });
  if (state.mode === "batch" && state.batch.size) {
    query.datasets = [...state.batch].sort((a, b) => a - b).join(",");
  }
  view.ctx.setQuery(query);
}
